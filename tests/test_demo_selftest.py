"""``soilvolume demo`` and ``soilvolume selftest`` on their success paths, and a self-test that
fails when the engine's volume is wrong (it must never pass a broken installation)."""

from __future__ import annotations

import json

import pytest
from conftest import run_cli

import soilvolume.api
from soilvolume.cli import main
from soilvolume.scenes.selftest import NET_TOLERANCE


def _table(stdout: str) -> dict[str, list[float]]:
    """The demo's volume table: {row: [net, cut, fill(, error %)]}."""
    rows = {}
    for line in stdout.splitlines():
        name, _, numbers = line.partition("  ")
        try:
            rows[name.strip()] = [float(v) for v in numbers.replace("%", "").split()]
        except ValueError:
            continue
    return rows


def test_demo_runs_end_to_end_and_prints_the_truth_beside_the_estimate(tmp_path):
    """Measured (small pair, seed 0): true +953.77 m3, estimated +951.50 (-0.24 %) +- 14.27 m3."""
    out = tmp_path / "demo"
    done = run_cli("demo", "--out", out)
    assert done.returncode == 0, done.stderr[-2000:]
    truth = json.loads((out / "data" / "truth.json").read_text())
    report = json.loads((out / "result" / "report.json").read_text())
    rows = _table(done.stdout)
    assert rows["true"] == pytest.approx([truth["net"], truth["cut"], truth["fill"]], abs=0.005)
    net, cut, fill, err = rows["change areas"]
    assert [net, cut, fill] == pytest.approx(
        [report["volume_change_areas_m3"][k] for k in ("net", "cut", "fill")], abs=0.005
    )
    assert abs(net - truth["net"]) <= 0.01 * truth["net"] and err == pytest.approx(
        100 * (net - truth["net"]) / truth["net"], abs=0.01
    )
    assert cut == pytest.approx(truth["cut"], rel=0.05) and fill == pytest.approx(truth["fill"], rel=0.01)
    assert abs(report["volume_m3"]["net"] - truth["net"]) <= report["uncertainty_m3"]["net"]
    assert f"95 % uncertainty of the net: +-{report['uncertainty_m3']['net']:.2f} m3" in done.stdout
    assert {"report.html", "difference.tif", "dem_before.tif", "dem_after.tif"} <= {
        p.name for p in (out / "result").iterdir()
    }
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # nothing staged left beside it


def test_selftest_passes_on_a_working_engine(tmp_path, capsys):
    assert main(["selftest", "--out", str(tmp_path / "run")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert abs(res["net_m3"] - res["true_net_m3"]) <= NET_TOLERANCE * res["true_net_m3"], res
    assert (tmp_path / "run" / "result" / "report.json").is_file()


@pytest.mark.parametrize("factor", [0.5, 1.2])
def test_selftest_fails_when_the_volume_is_wrong(tmp_path, capsys, monkeypatch, factor):
    """An engine whose net is off by -50 % or +20 % fails the self-test: one line naming both
    volumes, exit 1, nothing kept in the output folder."""
    real = soilvolume.api.estimate

    def wrong(*args, **kwargs):
        res = real(*args, **kwargs)
        res.report["volume_m3"]["net"] *= factor
        return res

    monkeypatch.setattr(soilvolume.api, "estimate", wrong)
    assert main(["selftest", "--out", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("soilvolume: error: self-test: net "), err
    assert err.endswith("where the seeded pair holds +953.8 m³"), err
    assert list(tmp_path.iterdir()) == []
