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
    whole = cell_heights(ids.copy(), z.copy(), shape, statistic, spread=True, skew=True)
    halves = cell_heights(ids.copy(), z.copy(), shape, statistic, spread=True, skew=True, own=True)
    assert len(whole) == len(halves) == 4
    for a, b in zip(whole, halves, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
    assert np.nansum(halves[1]) == n  # every point counted
