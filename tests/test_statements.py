"""What a run states in words agrees with what it reports (issue 49): the cautions quote the
interval the run reports, and a run judged not reliable makes no statement of confidence."""

from __future__ import annotations

from soilvolume.core.record import QualityInputs
from soilvolume.reporting.summary import significance
from soilvolume.volumes.quality import assess


def _report(net: float, half: float, bound: float, verdict: str | None = None) -> dict:
    """A report.json's parts the verdict and the significance read."""
    rep = {
        "volume_m3": {"net": net, "cut": 10.0, "fill": 10.0 + net},
        "uncertainty_m3": {"net": half, "confidence": 0.95},
        "registration": {"georeferencing": {"used": "precise"}},
        "excluded": {
            "moved_objects": {"count": 2, "excluded": True, "fill": 30.0, "cut": 0.0},
            "unclassified": {"count": 1, "fill": bound, "cut": 0.0, "signals": True},
            "bound_m3": {"net": bound},
        },
    }
    if verdict:
        rep["quality"] = {"verdict": verdict, "messages": []}
    return rep


def test_nonsoil_caution_quotes_the_reported_interval():
    """Tommy Thompson: '... more than the net's interval (±23.8 m3)' while the run reported ±48.97
    (the 23.8 left out the unclassified change's term). The caution now quotes ±48.97 and says
    what the smaller figure is; the verdict is the same (the unclassified change under a tenth of the
    volume moved)."""
    import numpy as np

    rep = _report(net=300.0, half=48.97, bound=25.17)
    z = np.zeros((4, 4))
    q = assess(rep, QualityInputs(z.astype(bool), z.astype(bool), z, None, 1.0, {}))
    said = [m for m in q["messages"] if "together more than" in m]
    assert len(said) == 1, q["messages"]
    assert "±48.97 m³" in said[0]
    assert "±23.80 m³" in said[0] and "could not be classified" in said[0]
    assert q["verdict"] == "use with caution"


def test_not_reliable_run_states_no_confidence():
    """Tommy Thompson's log: 'not reliable', then 'a significant gain (fill) at 95 % confidence'.
    A not-reliable run's sentence makes no statement of confidence; the others keep theirs."""
    said = significance(_report(4551.46, 2520.10, 0.0, "not reliable"))
    assert "significant" not in said and "not reliable" in said
    assert "+4,551.5" in said and "2,520.1" in said
    assert "significant gain (fill) at 95 % confidence" in significance(_report(4551.46, 2520.10, 0.0, "reliable"))
    caution = significance(_report(4551.46, 2520.10, 0.0, "use with caution"))
    assert "significant gain" in caution
    assert "not significant" in significance(_report(10.0, 20.0, 0.0, "use with caution"))


def test_a_not_reliable_verdict_lists_no_significance():
    """The verdict's reasons of a not-reliable run said 'it is not significant' too (a statement
    of confidence the run cannot make); now they give the reasons only, the verdict the same."""
    import numpy as np

    rep = _report(net=5.0, half=20.0, bound=0.0)
    rep["volume_m3"].update(cut=400.0, fill=405.0)  # the 30 m3 unclassified under a tenth of the volume moved
    rep["excluded"]["unclassified"] = {"count": 1, "fill": 30.0, "cut": 0.0, "signals": False}
    rep["excluded"]["bound_m3"] = {"net": 30.0}
    rep["uncertainty_m3"]["net"] = 40.0
    z = np.zeros((4, 4))
    q = assess(rep, QualityInputs(z.astype(bool), z.astype(bool), z, None, 1.0, {}))
    assert q["verdict"] == "not reliable", q
    assert not any("significant" in m for m in q["messages"]), q["messages"]
    rep["excluded"]["unclassified"]["signals"] = True  # a caution only: the significance is said
    q = assess(rep, QualityInputs(z.astype(bool), z.astype(bool), z, None, 1.0, {}))
    assert q["verdict"] == "use with caution" and any("not significant" in m for m in q["messages"]), q
