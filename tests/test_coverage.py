"""Coverage of the after footprint: measured on the grid and beyond it, summed over tiles as on
the whole grid, and gated in the verdict (a before survey that misses the works is never "no
change")."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.core.types import GridSpec
from soilvolume.volumes import coverage


def _grids(gap: bool = True):
    rng = np.random.default_rng(1)
    shape = (60, 80)
    n_a = np.full(shape, 10)
    n_a[:, 70:] = 0  # the after survey stops at column 70
    n_b = np.full(shape, 12)
    d = rng.normal(0, 0.03, shape)
    d[20:30, 20:30] += 1.5  # a pile
    if gap:
        n_b[15:35, 15:35] = 0  # no before data under the pile and around it
    d[(n_a == 0) | (n_b == 0)] = np.nan
    return n_a, n_b, np.zeros(shape, bool), d, n_a.copy()  # no point that is not soil


def test_counts_of_a_gap_under_the_works():
    c = coverage.counts(*_grids())
    assert c["after_cells"] == 60 * 70 and c["before_missing_cells"] == 400
    assert c["compared_cells"] == 60 * 70 - 400
    assert c["gap_ring_cells"] > 0 and c["gap_ring_p95_m"] < 0.1  # the pile is inside the gap


def test_tiles_add_up_to_the_whole_grid():
    n_a, n_b, refilled, d, shown = _grids()
    whole = coverage.counts(n_a, n_b, refilled, d, shown)
    parts, h = [], 3
    for r0, r1 in ((0, 30), (30, 60)):
        for c0, c1 in ((0, 40), (40, 80)):
            e = (max(0, r0 - h), min(60, r1 + h), max(0, c0 - h), min(80, c1 + h))
            win = (slice(e[0], e[1]), slice(e[2], e[3]))
            core = (slice(r0 - e[0], r1 - e[0]), slice(c0 - e[2], c1 - e[2]))
            edges = (e[0] == 0, e[1] == 60, e[2] == 0, e[3] == 80)
            parts.append(coverage.counts(n_a[win], n_b[win], refilled[win], d[win], shown[win], core, edges))
    total = coverage.combine(parts)
    for key in coverage.COUNTS:
        assert total[key] == whole[key], key
    assert total["gap_ring_p95_m"] == pytest.approx(whole["gap_ring_p95_m"], rel=0.3)


def test_the_verdict_of_a_half_covered_survey():
    cells = coverage.counts(*_grids())
    cov = coverage.summary(cells, 1.0, 0.0, 0.08)
    assert cov["unseen_m2"] == 400 and cov["compared_share"] == pytest.approx(1 - 400 / 4200)
    report = {"coverage": cov, "uncertainty_m3": {"net": 0.0}}
    severity, text = coverage.check(report)
    assert severity == "unreliable"
    assert text.startswith("the before survey does not cover 400 m² (10%) of the after footprint")
    full = coverage.summary(coverage.counts(*_grids(gap=False)), 1.0, 0.0, 0.08)
    assert full["compared_share"] == 1.0 and coverage.check({"coverage": full, "uncertainty_m3": {"net": 0.0}}) is None


def test_a_small_gap_at_quiet_ground_is_a_caution():
    n_a, n_b, refilled, d, shown = _grids(gap=False)
    n_b[50:55, 5:10] = 0  # 25 cells (0.6 %) far from the works
    d[50:55, 5:10] = np.nan
    cov = coverage.summary(coverage.counts(n_a, n_b, refilled, d, shown), 1.0, 0.0, 0.08)
    severity, text = coverage.check({"coverage": cov, "uncertainty_m3": {"net": 20.0}})
    assert severity == "caution" and "25 m²" in text and "within their interval" in text, text
    bound = cov["unseen_volume_bound_m3"]
    assert bound > 0
    moved = {"cut": 30.0 * bound, "fill": 69.0 * bound}  # 1 % of the moved volume is 0.99 bound: it could tip the net
    assert coverage.check({"coverage": cov, "uncertainty_m3": {"net": 20.0}, "volume_m3": moved})[0] == "caution"
    moved["fill"] = 80.0 * bound  # 1.1 bound: it cannot move the net past its tolerance, so the verdict is silent
    assert coverage.check({"coverage": cov, "uncertainty_m3": {"net": 20.0}, "volume_m3": moved}) is None


def test_a_gap_of_the_after_survey_over_the_before_ground_is_unseen():
    """Water standing in a pit (or a pit the camera could not see into) leaves the after survey without any
    point where the before saw ground: change there is not measured, so it is unseen, not outside the survey;
    a gap the after survey shows vegetation in, and one neither survey saw, are not."""
    n_a, n_b, refilled, d, shown = _grids(gap=False)
    d[20:30, 20:30] -= 3.0  # a pit where the pile was
    n_a[22:28, 22:28], shown[22:28, 22:28] = 0, 0  # water in it: no return at all
    d[22:28, 22:28] = np.nan
    cells = coverage.counts(n_a, n_b, refilled, d, shown)
    assert cells["after_cells"] == 60 * 70 and cells["compared_cells"] == 60 * 70 - 36
    assert cells["before_missing_cells"] == 0 and cells["gap_ring_p95_m"] > 1.0  # the pit's walls around it
    cov = coverage.summary(cells, 1.0, 0.0, 0.08)
    assert cov["unseen_m2"] == 36 and cov["unseen_volume_bound_m3"] > 36 * 1.0
    severity, text = coverage.check({"coverage": cov, "uncertainty_m3": {"net": 5.0}})
    assert severity == "unreliable" and text.startswith("the surveys do not both cover 36 m²"), text
    shown[22:28, 22:28] = 4  # the after survey's points there are vegetation: not a gap in it
    assert coverage.counts(n_a, n_b, refilled, d, shown)["after_cells"] == 60 * 70 - 36
    shown[22:28, 22:28], n_b[22:28, 22:28] = 0, 0  # a pond in both surveys: nobody saw that ground
    assert coverage.counts(n_a, n_b, refilled, d, shown)["after_cells"] == 60 * 70 - 36


def test_the_after_survey_beyond_the_grid():
    grid = GridSpec(xmin=0.0, ymax=10.0, cell=1.0, rows=10, cols=10)
    xy = np.array([[0.5, 5.0, 0], [12.5, 5.5, 0], [12.6, 5.4, 0], [14.5, 5.5, 0], [5.0, -3.5, 0]])
    assert coverage.outside(xy, grid, None, None)[0] == 3.0  # three cells of the lattice beyond the grid
