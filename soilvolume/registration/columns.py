"""Terrain surfaces for registration: each occupied grid column one point at its mean, normals from
the gradient of the smoothed column heights (a few array passes, not k-d tree normal estimation)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..core.cells import bounds, cell_index, in_box, rows
from ..native import axes as native_axes
from ..native import kernels, zeros


@dataclass
class Columns:
    """Column means of a cloud on a grid of ``cell`` m from ``lo`` (local x/y)."""

    xyz: np.ndarray  # (M, 3) column means
    row: np.ndarray  # (M,) grid row (y) of each column
    col: np.ndarray  # (M,) grid column (x)
    shape: tuple[int, int]
    lo: np.ndarray
    cell: float


class Cloud:
    """A cloud (N, 3) with its cuts to boxes remembered (a superset in order gives the same per-cell
    sums): a box is served from the tightest cut holding it, else cut anew with :data:`SLACK` m of
    room. Cuts are kept as (3, M) rows and handed out transposed."""

    SLACK = 2.0  # m around a new cut, so that the nearby boxes asked next fit in it
    TIGHT = 1.3  # a remembered cut serves a box when its area is at most this many times the box's

    def __init__(self, xyz: np.ndarray) -> None:
        self.xyz = xyz
        self._cuts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._box: tuple[np.ndarray, np.ndarray] | None = None

    @staticmethod
    def points(xyz: np.ndarray | Cloud) -> np.ndarray:
        return xyz.xyz if isinstance(xyz, Cloud) else xyz

    def within(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The points in a superset of the box lo..hi (x/y, edges included), in the cloud's order."""
        if len(self.xyz) == 0:
            return self.xyz
        if self._box is None:
            self._box = bounds(self.xyz, 2)
        if (self._box[0] >= lo).all() and (self._box[1] <= hi).all():
            return self.xyz
        base, blo, bhi = self.xyz, np.full(2, -np.inf), np.full(2, np.inf)
        for clo, chi, pts in self._cuts:  # the smallest remembered cut that holds the box
            if (clo <= lo).all() and (chi >= hi).all() and np.prod(chi - clo) < np.prod(bhi - blo):
                base, blo, bhi = pts.T, clo, chi
        if np.prod(bhi - blo) <= self.TIGHT * np.prod(hi - lo):
            return base
        clo, chi = np.maximum(lo - self.SLACK, blo), np.minimum(hi + self.SLACK, bhi)
        cut = _cut(base, clo, chi)
        self._cuts.append((clo, chi, cut))
        return cut.T


def _cut(base: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The (3, M) rows of the points of ``base`` (N, 3) in the x/y box lo..hi, in order (``sv_cut_box``
    when built)."""
    lib = kernels()
    if lib is None:
        return np.ascontiguousarray(rows(base, in_box(base, lo, hi)).T, dtype=np.float64)
    base, axes, step = native_axes(base, np.float64)
    box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    m = lib.sv_cut_box(*axes, len(base), step, *box, None, 0)
    cut = np.empty((3, m))
    lib.sv_cut_box(*axes, len(base), step, *box, cut.ctypes.data, m)
    return cut


Target = np.ndarray | Cloud  # a target cloud: an array, or one with its box cuts remembered


def columns(xyz: Target, cell: float, lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> Columns:
    """Mean point of every occupied ``cell`` x ``cell`` column (points outside lo..hi dropped); given a
    box, only its points with a cell of margin are binned (the same sums)."""
    pts, cut = Cloud.points(xyz), lo is not None  # a box is given whole or not at all
    lo, hi = (np.asarray(lo[:2], float), np.asarray(hi[:2], float)) if cut else bounds(pts, 2)
    shape = (int((hi[1] - lo[1]) // cell) + 1, int((hi[0] - lo[0]) // cell) + 1)
    if cut:
        box = (lo - cell, lo + (np.array(shape[::-1]) + 1) * cell)
        pts = xyz.within(*box) if isinstance(xyz, Cloud) else rows(xyz, in_box(xyz, *box))
    return _binned(pts, lo, float(cell), shape)


def _binned(xyz: np.ndarray, lo: np.ndarray, cell: float, shape: tuple[int, int]) -> Columns:
    """:func:`columns` of ``xyz`` on the grid from ``lo``: cells ``floor((v - lo) / cell)`` in float
    (exact integers), points off the grid in one dropped extra bin."""
    if kernels() is not None and len(xyz):
        return _native_binned(kernels(), xyz, lo, cell, shape)
    n = shape[0] * shape[1]
    fx, fy = (np.floor((xyz[:, k] - lo[k]) / cell) for k in (0, 1))  # the values of ``cell_index`` before the cast
    off = ~((fx >= 0) & (fy >= 0) & (fx < shape[1]) & (fy < shape[0]))
    fy *= shape[1]
    fy += fx
    fy[off] = n
    ids = fy.astype(np.int64)
    count = np.bincount(ids, minlength=n + 1)[:n]
    has = np.flatnonzero(count)
    means = np.empty((len(has), 3))
    for k in range(3):
        means[:, k] = np.bincount(ids, weights=xyz[:, k], minlength=n + 1)[has] / count[has]
    return Columns(means, has // shape[1], has % shape[1], shape, lo, cell)


def _native_binned(lib, xyz: np.ndarray, lo: np.ndarray, cell: float, shape: tuple[int, int]) -> Columns:
    """:func:`_binned` by ``sv_columns``: the same bits."""
    n = shape[0] * shape[1]
    xyz, axes, step = native_axes(xyz, np.float64)
    count, sums = zeros("columns_count", n, np.int64), zeros("columns_sums", 3 * n, np.float64)
    has, means = np.empty(min(n, len(xyz)), np.int64), np.empty((min(n, len(xyz)), 3))
    m = lib.sv_columns(
        *axes, len(xyz), step, float(lo[0]), float(lo[1]), float(cell), shape[0], shape[1],
        count.ctypes.data, sums.ctypes.data, has.ctypes.data, means.ctypes.data,
    )  # fmt: skip
    has, means = has[:m], means[:m]
    return Columns(means, has // shape[1], has % shape[1], shape, lo, cell)


def column_surface(
    xyz: Target, voxel: float, lo: np.ndarray | None = None, hi: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The column means of ``xyz`` (within lo..hi) and their surface normals."""
    cols = columns(xyz, voxel, lo, hi)
    return cols.xyz, normals(cols)


def normals(c: Columns) -> np.ndarray:
    """Upward unit normals from the gradient of the column heights (Gaussian smoothed by one cell,
    normalized convolution over empty columns)."""
    flat = c.row * c.shape[1] + c.col
    h, w = np.zeros(c.shape), np.zeros(c.shape)
    h.ravel()[flat] = c.xyz[:, 2]  # h * w is h itself: 0 where w is 0, h * 1.0 elsewhere
    w.ravel()[flat] = 1.0
    hs, ws = scipy.ndimage.gaussian_filter(h, 1.0), scipy.ndimage.gaussian_filter(w, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(ws > 1e-3, hs / ws, 0.0)
    gy, gx = _gradient(h, ws > 1e-3, c.cell)
    gx, gy = gx.ravel()[flat], gy.ravel()[flat]
    norm = np.sqrt((gx * gx + gy * gy) + 1.0)  # |(-gx, -gy, 1)| summed in that order
    return np.column_stack([-gx, -gy, np.ones_like(gx)]) / norm[:, None]


def _gradient(h: np.ndarray, valid: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(dz/dy, dz/dx): central differences where both neighbours are valid, one-sided where one is, 0
    where none (the sum of the valid differences over their count)."""
    out = []
    for hh, vv in ((h, valid), (h.T, valid.T)):
        ok = (vv[1:] & vv[:-1]).astype(float)
        step = np.where(ok > 0, hh[1:] - hh[:-1], 0.0)
        after, before = ((0, 1), (0, 0)), ((1, 0), (0, 0))  # each cell's forward and backward difference
        num = np.pad(step, after) + np.pad(step, before)  # an end's missing one is 0.0: -0.0 becomes 0.0
        den = np.pad(ok, after) + np.pad(ok, before)
        g = np.where(den > 0, num / np.maximum(den, 1) / cell, 0.0)
        out.append(g if hh is h else g.T)
    return out[0], out[1]


def plane_residuals(points: np.ndarray, c: Columns, n: np.ndarray) -> np.ndarray:
    """Each point's distance to the tangent plane of its column (NaN over empty columns, off grid)."""
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
