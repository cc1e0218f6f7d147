"""Terrain surfaces for registration: a cloud summarised on a regular grid of columns.

Each occupied column becomes one point at its mean x, y, z; the target's normals come from the
gradient of the (lightly smoothed) column heights. On 2.5D terrain this replaces voxel
down-sampling plus k-d tree normal estimation (seconds on ~10^5 points) by a few array passes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..core.cells import bounds, cell_index, in_box, rows


@dataclass
class Columns:
    """Column means of a cloud on a grid of ``cell`` m from ``lo`` (local x/y)."""

    xyz: np.ndarray  # (M, 3) column means
    row: np.ndarray  # (M,) grid row (y) of each column
    col: np.ndarray  # (M,) grid column (x)
    shape: tuple[int, int]
    lo: np.ndarray
    cell: float


def columns(xyz: np.ndarray, cell: float, lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> Columns:
    """Mean point of every occupied ``cell`` x ``cell`` column (points outside lo..hi dropped).
    Given a box, the points are first cut to it with a cell of margin (a superset of the points
    the grid keeps, in their order: the same sums, on a fraction of a large target's points)."""
    if lo is None or hi is None:
        box = bounds(xyz, 2)
    cut = lo is not None and hi is not None
    lo = box[0] if lo is None else np.asarray(lo[:2], float)
    hi = box[1] if hi is None else np.asarray(hi[:2], float)
    shape = (int((hi[1] - lo[1]) // cell) + 1, int((hi[0] - lo[0]) // cell) + 1)
    if cut:
        xyz = rows(xyz, in_box(xyz, lo - cell, lo + (np.array(shape[::-1]) + 1) * cell))
    ix, iy = cell_index(xyz[:, 0], lo[0], cell), cell_index(xyz[:, 1], lo[1], cell)
    ok = (ix >= 0) & (iy >= 0) & (ix < shape[1]) & (iy < shape[0])
    every = bool(ok.all())
    ids = iy * shape[1] + ix if every else iy[ok] * shape[1] + ix[ok]
    n = shape[0] * shape[1]
    count = np.bincount(ids, minlength=n)
    has = np.flatnonzero(count)
    means = np.empty((len(has), 3))
    for k in range(3):
        w = xyz[:, k] if every else np.compress(ok, xyz[:, k])
        means[:, k] = np.bincount(ids, weights=w, minlength=n)[has] / count[has]
    return Columns(means, has // shape[1], has % shape[1], shape, lo, float(cell))


def normals(c: Columns, smooth: float = 1.0) -> np.ndarray:
    """Upward unit normals of the column surface from the gradient of its heights (Gaussian
    smoothed by ``smooth`` cells, normalized convolution over empty columns)."""
    h = np.zeros(c.shape)
    w = np.zeros(c.shape)
    h[c.row, c.col] = c.xyz[:, 2]
    w[c.row, c.col] = 1.0
    if smooth > 0:
        hs, ws = ndimage.gaussian_filter(h * w, smooth), ndimage.gaussian_filter(w, smooth)
        with np.errstate(invalid="ignore", divide="ignore"):
            h = np.where(ws > 1e-3, hs / ws, 0.0)
        w = (ws > 1e-3).astype(float)
    gy, gx = _gradient(h, w > 0, c.cell)
    n = np.stack([-gx[c.row, c.col], -gy[c.row, c.col], np.ones(len(c.row))], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _gradient(h: np.ndarray, valid: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(dz/dy, dz/dx) with central differences where both neighbours are valid, one-sided where
    one is, 0 where none (y grows with the row index here)."""
    out = []
    for axis in (0, 1):
        fwd = np.zeros_like(h)
        bwd = np.zeros_like(h)
        okf = np.zeros_like(valid)
        okb = np.zeros_like(valid)
        sl = [slice(None)] * 2
        a, b = list(sl), list(sl)
        a[axis], b[axis] = slice(0, -1), slice(1, None)
        fwd[tuple(a)] = h[tuple(b)] - h[tuple(a)]
        okf[tuple(a)] = valid[tuple(b)] & valid[tuple(a)]
        bwd[tuple(b)] = h[tuple(b)] - h[tuple(a)]
        okb[tuple(b)] = okf[tuple(a)]
        num = np.where(okf, fwd, 0.0) + np.where(okb, bwd, 0.0)
        den = okf.astype(float) + okb.astype(float)
        out.append(np.where(den > 0, num / np.maximum(den, 1) / cell, 0.0))
    return out[0], out[1]


def plane_residuals(points: np.ndarray, c: Columns, n: np.ndarray) -> np.ndarray:
    """Point-to-plane distance of each point to the tangent plane of the column it falls in
    (NaN for points over empty columns or off the grid)."""
    ix, iy = cell_index(points[:, 0], c.lo[0], c.cell), cell_index(points[:, 1], c.lo[1], c.cell)
    ok = (ix >= 0) & (iy >= 0) & (ix < c.shape[1]) & (iy < c.shape[0])
    lut = np.full(c.shape[0] * c.shape[1], -1, np.int64)
    lut[c.row * c.shape[1] + c.col] = np.arange(len(c.row))
    j = np.full(len(points), -1, np.int64)
    j[ok] = lut[iy[ok] * c.shape[1] + ix[ok]]
    r = np.full(len(points), np.nan)
    m = j >= 0
    r[m] = np.einsum("ij,ij->i", points[m] - c.xyz[j[m]], n[j[m]])
    return r
