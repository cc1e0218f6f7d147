"""The change the change areas leave out at their edges (issue 53): a lowering or a pile whose edge runs out
under the detection level loses its skirt from the headline; the interval carries the difference summed in
the ring around each part's areas, where it has the part's sign (noise sums to about nothing)."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.volumes.change import SKIRT_CELLS, broad_terms, skirt_terms

CELL_AREA = 0.25


def _compaction(noise: float = 0.0):
    """A 0.2 m lowering over 5 x 5 m whose edge runs out over 1.5 m (three cells), on quiet ground."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:80, 0:80]
    dist = np.maximum(np.abs(yy - 39.5), np.abs(xx - 39.5)) - 5.0  # cells outside the 10 x 10 core
    d = -0.2 * np.clip(1.0 - dist / SKIRT_CELLS, 0.0, 1.0)
    return d + rng.normal(0.0, noise, d.shape)


def test_the_skirt_of_a_lowering_under_the_detection_level():
    d = _compaction()
    cut = d < -0.1  # the areas stop halfway down the edge
    left_out = -float(d[~cut].sum()) * CELL_AREA
    assert left_out > 1.5  # m3: a fifth of the lowering
    terms = skirt_terms(d, np.zeros(d.shape, bool), cut, CELL_AREA)
    assert terms["cut"] == pytest.approx(left_out, rel=0.05)
    assert terms["fill"] == 0.0 and terms["net"] == pytest.approx(terms["cut"])


def test_noise_around_the_areas_sums_to_about_nothing():
    d = _compaction(noise=0.03)
    d[np.abs(d) < 0.2] = np.random.default_rng(4).normal(0.0, 0.03, int((np.abs(d) < 0.2).sum()))  # no skirt
    cut = d < -0.1
    cut[:] = False
    cut[35:45, 35:45] = True  # the lowering's core only
    assert skirt_terms(d, np.zeros(d.shape, bool), cut, CELL_AREA)["cut"] < 0.5  # m3, against about 2 of a skirt


def test_the_caution_names_the_skirt_when_it_is_the_largest_part():
    """A wide interval's caution names its largest part in m³; the other terms by their own names (a compaction's
    edge under the detection level is not "what is not soil")."""
    from soilvolume.volumes.tolerance import tolerance_check

    report = {
        "volume_m3": {"net": -40.0, "cut": 40.0, "fill": 0.0},
        "uncertainty_m3": {"net": 6.0, "cut": 6.0, "fill": 0.1},
        "uncertainty": {
            "confidence": 0.95,
            "terms_m3": {"net": [0.5, 0.4, 0.1, 0.1, 3.0]},  # one-sigma; the last: the other terms
            "skirt_m3": {"net": 2.9, "cut": 2.9, "fill": 0.0},
            "registration_m3": {"net": -0.4, "cut": 0.3, "fill": 0.1},
            "classification_m3": {"net": 0.2, "cut": 0.2, "fill": 0.0},
        },
    }
    [(severity, text)] = tolerance_check(report)
    assert severity == "caution" and "net's 95 % interval (±6.0 m³)" in text
    assert text.endswith("its largest part is change at the works' edges under the detection level (±5.7 m³)"), text


def test_a_settlement_wide_under_the_detection_level_is_in_the_interval():
    """A 0.06 m settlement over 15 x 15 m, away from any change area, on ground with 4 cm of noise per cell: no
    cell of it reaches the detection level (about 8 cm), so no area counts it; the blocks of about 5 m it covers
    stand out of the others' spread and the cut's interval carries their change. Noise alone, or a settlement
    where the survey shows no soil (left out as not soil), carries none."""
    rng = np.random.default_rng(5)
    d = rng.normal(0.0, 0.04, (120, 120))
    d[60:90, 60:90] -= 0.06
    none = np.zeros(d.shape, bool)
    soil = np.ones(d.shape, bool)
    settled = 0.06 * 30 * 30 * CELL_AREA  # 13.5 m3
    terms = broad_terms(d, none, none, soil, 0.5, 0.08)
    assert terms["cut"] == pytest.approx(settled, rel=0.35) and terms["fill"] < 0.1 * settled
    assert broad_terms(rng.normal(0.0, 0.04, d.shape), none, none, soil, 0.5, 0.08)["cut"] < 0.1 * settled
    soil[55:95, 55:95] = False
    assert broad_terms(d, none, none, soil, 0.5, 0.08)["cut"] < 0.1 * settled
