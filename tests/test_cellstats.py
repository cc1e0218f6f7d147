"""Per-cell statistics through one sort of (cell, height) keys (issue 22): a large epoch's keys
sorted as two halves on two threads give the bits of one sort."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.dem import cellstats
from soilvolume.dem.cellstats import cell_heights


@pytest.mark.parametrize("statistic", ["robust-mean", "median", "mean"])
@pytest.mark.parametrize("layout", ["flight-lines", "one-cell", "last-cells"])
def test_two_sorted_halves_give_the_one_sort_s_statistics(statistic, layout, monkeypatch):
    """Cells visited in flight-line order with strays, every point in one cell (one half empty),
    and the points all in the last cells: the statistics, spreads and skews of the caller's arrays
    sorted as two halves (``own``) equal those of one sort, bit for bit."""
    monkeypatch.setattr(cellstats, "SPLIT_SORT", 50_000)
    rng = np.random.default_rng(7)
    shape, n = (120, 150), 400_000
    cells = shape[0] * shape[1]
    if layout == "flight-lines":
        ids = np.sort(rng.integers(0, cells, n))
        ids[::9] = rng.integers(0, cells, len(ids[::9]))
    elif layout == "one-cell":
        ids = np.full(n, 4321)
    else:
        ids = rng.integers(cells - 40, cells, n)
    z = rng.normal(50.0, 1.5, n) + 0.01 * (ids % 97)
    whole = cell_heights(ids.copy(), z.copy(), shape, statistic, full=True)
    halves = cell_heights(ids.copy(), z.copy(), shape, statistic, full=True, own=True)
    assert len(whole) == len(halves) == 4
    for a, b in zip(whole, halves, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
    assert np.nansum(halves[1]) == n  # every point counted


@pytest.mark.parametrize("statistic", ["robust-mean", "median", "mean"])
def test_a_window_of_the_grid_gives_the_whole_grids_cells_bit_for_bit(statistic):
    """Heights are quantised on one lattice (``rint(z / q)``), not from each call's lowest point:
    a window's cells computed from its own points equal the whole grid's, bit for bit, whatever
    the window's lowest point (a tiled run's tiles and a run in one process give one DEM)."""
    rng = np.random.default_rng(11)
    shape, n = (60, 80), 200_000
    rows, cols = rng.integers(0, shape[0], n), rng.integers(0, shape[1], n)
    z = 40.0 + 0.05 * rows + 0.02 * cols + rng.normal(0, 0.3, n)  # each window's lowest point its own
    z[rng.random(n) < 0.03] += 2.0  # strays the robust mean trims
    whole = cell_heights(rows * shape[1] + cols, z, shape, statistic, full=True)
    for r0, r1, c0, c1 in [(0, 30, 0, 40), (30, 60, 40, 80), (10, 50, 20, 70), (59, 60, 0, 80)]:
        inside = (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
        ids = (rows[inside] - r0) * (c1 - c0) + (cols[inside] - c0)
        part = cell_heights(ids, z[inside], (r1 - r0, c1 - c0), statistic, full=True)
        for a, b in zip(whole, part, strict=True):
            assert np.array_equal(a[r0:r1, c0:c1], b, equal_nan=True), (statistic, (r0, r1, c0, c1))
