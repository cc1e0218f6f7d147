"""An overview of a grid too large for one process: the k x k block sums the gridding tasks
return, the overview grid they add up to, each epoch's median point count from the tasks' count
histograms, the overview's correction brought back to cells."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..core.types import GridSpec

RASTER_BYTES_PER_CELL = 200.0  # the volume step's peak per grid cell (arrays, labels, solver)
COUNT_CAP = 1 << 16  # counts above this are one histogram bin (the median is far below)


MAX_CELLS = 2_000_000  # the overview's cells at most: its volume step runs in the driver (~50 s)


def factor(grid: GridSpec, budget_gb: float) -> int:
    """The smallest power of 2 k whose k x k blocks bring the grid's volume step within half of
    the memory budget (1: the whole grid fits)."""
    return blocks_for(grid, budget_gb * 2**30 * 0.5 / RASTER_BYTES_PER_CELL)


def blocks_for(grid: GridSpec, cells: float) -> int:
    """The smallest power of 2 k with at most ``cells`` blocks of k x k grid cells."""
    k = 1
    while grid.rows * grid.cols / (k * k) > cells:
        k *= 2
    return k


def coarse(grid: GridSpec, k: int) -> GridSpec:
    """The overview grid: cells of k x k grid cells, from the same corner."""
    return replace(grid, cell=grid.cell * k, rows=math.ceil(grid.rows / k), cols=math.ceil(grid.cols / k))


def block_sums(win, k: int, h: np.ndarray, n: np.ndarray) -> tuple:
    """(first block row, first block col, (height sum, valid cells, count sum)) of a tile's k x k
    blocks on the grid's block lattice (blocks cut by tile edges get the rest from the next tile)."""
    r0, r1, c0, c1 = win
    br = np.arange(r0, r1) // k - r0 // k
    bc = np.arange(c0, c1) // k - c0 // k
    shape = (int(br[-1]) + 1, int(bc[-1]) + 1)
    ids = (br[:, None] * shape[1] + bc[None, :]).ravel()
    hv, nv = h.ravel(), n.ravel()
    ok = np.isfinite(hv)
    size = shape[0] * shape[1]
    sums = (
        np.bincount(ids[ok], hv[ok], minlength=size),
        np.bincount(ids[ok], minlength=size).astype(float),
        np.bincount(ids, nv.astype(float), minlength=size),
    )
    return r0 // k, c0 // k, tuple(s.reshape(shape) for s in sums)


def count_histogram(n: np.ndarray) -> np.ndarray:
    """Histogram of the non-zero point counts of a tile's cells (summed across tiles)."""
    has = n[n > 0]
    return np.bincount(np.minimum(has, COUNT_CAP).astype(np.int64), minlength=COUNT_CAP + 1)


def median_from_histogram(hist: np.ndarray) -> float:
    """``np.median`` of the values a histogram of integers counts (NaN when empty)."""
    total = int(hist.sum())
    if total == 0:
        return float("nan")
    cum = np.cumsum(hist)
    lo = int(np.searchsorted(cum, (total - 1) // 2 + 1))  # the (total-1)//2-th value (0-based)
    hi = int(np.searchsorted(cum, total // 2 + 1))
    return (lo + hi) / 2.0


def add_blocks(target: tuple[np.ndarray, ...], part: tuple) -> None:
    """Add one tile's :func:`block_sums` into the overview's (sum, valid, count) arrays."""
    b0, c0, sums = part
    for full, s in zip(target, sums, strict=True):
        full[b0 : b0 + s.shape[0], c0 : c0 + s.shape[1]] += s


def to_cells(values: np.ndarray, k: int, win, nearest: bool = False) -> np.ndarray:
    """An overview raster on the cells of window ``win``: bilinear between block centres (NaN
    blocks take their nearest finite block's value first), or ``nearest`` the block's value."""
    from scipy import ndimage

    r0, r1, c0, c1 = win
    if nearest:
        return values[np.arange(r0, r1)[:, None] // k, np.arange(c0, c1)[None, :] // k]
    v = np.asarray(values, float)
    bad = ~np.isfinite(v)
    if bad.all():
        return np.zeros((r1 - r0, c1 - c0))
    if bad.any():
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        v = v[tuple(idx)]
    rr = (np.arange(r0, r1) + 0.5) / k - 0.5
    cc = (np.arange(c0, c1) + 0.5) / k - 0.5
    coords = np.meshgrid(rr, cc, indexing="ij")
    return ndimage.map_coordinates(v, coords, order=1, mode="nearest")
