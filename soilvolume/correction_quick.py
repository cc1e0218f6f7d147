"""Registration helper: remove the after cloud's smooth deformation and drop its change areas
before the last ICP levels (coarse 1 m median grids, robust degree-2 fit)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .grid import average_height, make_grid


def _design(x: np.ndarray, y: np.ndarray, scale: float) -> np.ndarray:
    x, y = x / scale, y / scale
    return np.c_[np.ones_like(x), x, y, x * x, x * y, y * y]


def detrend_for_registration(
    source: np.ndarray, target: np.ndarray, cell: float = 1.0, iterations: int = 4,
) -> np.ndarray:
    """Source points (already in the target frame) with the fitted degree-2 difference surface
    removed from z and the points of change cells (and cells without target data) dropped."""
    lo, hi = source.min(axis=0), source.max(axis=0)
    grid = make_grid(lo, hi, cell, np.zeros(3), None)
    hs, _ = average_height(source, grid, "median")
    ht, _ = average_height(target, grid, "median")
    diff = hs - ht
    valid = np.isfinite(diff)
    if valid.sum() < 20:
        return source[:0]
    x, y = grid.centers_local()
    scale = max(float(np.ptp(x)), float(np.ptp(y)), 1.0)
    stable = valid.copy()
    coef = np.zeros(6)
    for _ in range(iterations):
        a = _design(x[stable], y[stable], scale)
        coef, *_ = np.linalg.lstsq(a, diff[stable], rcond=None)
        resid = diff - (_design(x.ravel(), y.ravel(), scale) @ coef).reshape(diff.shape)
        r = resid[stable]
        sigma = 1.4826 * np.median(np.abs(r - np.median(r)))
        change = valid & (np.abs(resid) > max(3 * sigma, 0.05))
        change = ndimage.binary_dilation(change, iterations=2)
        new_stable = valid & ~change
        if new_stable.sum() < 20 or np.array_equal(new_stable, stable):
            break
        stable = new_stable
    row, col, ok = grid.index(source[:, :2])
    keep = np.zeros(len(source), dtype=bool)
    keep[ok] = stable[row[ok], col[ok]]
    out = source[keep].copy()
    out[:, 2] -= _design(out[:, 0], out[:, 1], scale) @ coef
    return out
