"""The Simple Morphological Filter (Pingel et al. 2013) as PDAL's filters.smrf implements it: ZImin,
the lowest Z per ``cell``, empty cells the mean of the 8 nearest; low outliers by the progressive
filter on -ZImin (slope 5, one pixel); objects where openings of ZImin by diamonds of radius
1..ceil(window/cell) differ by more than slope * cell * radius; ZIpro, ZImin without those, refilled;
ground where |ZIpro - z| <= threshold + scalar * slope(ZIpro) (last and single returns only)."""

from __future__ import annotations

import math

import numpy as np

from ..core.cells import cell_index

CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


def morph(a: np.ndarray, radius: int, op: str) -> np.ndarray:
    """Grey "erosion" or "dilation" by the diamond of ``radius``: scipy.ndimage's with the 5-point cross,
    iterated; edges repeated, so neighbours outside the raster are ignored, as in PDAL's erodeDiamond and
    dilateDiamond (a zero's sign may differ: openings are only compared)."""
    from scipy import ndimage  # here, as cKDTree below

    for _ in range(radius):
        a = getattr(ndimage, f"grey_{op}")(a, footprint=CROSS, mode="nearest")
    return a


def knnfill(z: np.ndarray, cell: float) -> np.ndarray:
    """Fill NaN cells with the mean of the (up to) 8 nearest non-NaN cell centres."""
    from scipy.spatial import cKDTree  # here: a Dask worker imports this module, never filters

    empty = np.isnan(z)
    if not empty.any() or empty.all():
        return z
    rows, cols = np.indices(z.shape)
    full = ~empty
    tree = cKDTree(np.column_stack([cols[full], rows[full]]) * cell)
    k = min(8, int(full.sum()))
    _, idx = tree.query(np.column_stack([cols[empty], rows[empty]]) * cell, k=k, workers=-1)
    out = z.copy()
    out[empty] = z[full][idx.reshape(idx.shape[0], -1)].mean(axis=1)
    return out


def progressive(zi: np.ndarray, cell: float, slope: float, max_window: float) -> np.ndarray:
    """Object mask of the progressive morphological filter."""
    max_radius = int(math.ceil(max_window / cell))
    prev, erosion = zi, zi
    obj = np.zeros(zi.shape, dtype=bool)
    for radius in range(1, max_radius + 1):
        erosion = morph(erosion, 1, "erosion")
        opening = morph(erosion, radius, "dilation")
        obj |= np.abs(prev - opening) > slope * cell * radius
        prev = opening
    return obj


def _gradient(a: np.ndarray, axis: int) -> np.ndarray:
    if a.shape[axis] < 2:
        return np.zeros_like(a)
    return np.gradient(a, axis=axis)  # central inside, one-sided at the edges (MATLAB's)


def smrf_classify(x, y, z, *, cell=1.0, slope=0.15, window=18.0, threshold=0.5, scalar=1.25) -> np.ndarray:
    """Ground flags (True = ground) for the given points."""
    minx, miny = float(x.min()), float(y.min())
    cols = int((float(x.max()) - minx) / cell + 1)
    rows = int((float(y.max()) - miny) / cell + 1)
    c, r = cell_index(x, minx, cell), cell_index(y, miny, cell)
    flat = r * cols + c
    zimin = np.full(rows * cols, np.inf)
    np.minimum.at(zimin, flat, z)
    zimin[np.isinf(zimin)] = np.nan
    zimin = knnfill(zimin.reshape(rows, cols), cell)
    low = progressive(-zimin, cell, 5.0, cell)
    obj = progressive(zimin, cell, slope, window)
    zipro = knnfill(np.where(obj | low, np.nan, zimin), cell)
    scaled = zipro / cell
    gsurf = np.hypot(_gradient(scaled, 1), _gradient(scaled, 0))
    gsurf = knnfill(gsurf, cell)
    thresh = threshold + scalar * gsurf
    zp, tp = zipro.ravel()[flat], thresh.ravel()[flat]
    return np.abs(zp - z) <= tp  # NaN comparisons are False: not ground, as PDAL skips them
