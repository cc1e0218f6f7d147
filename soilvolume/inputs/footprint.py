"""Alignment initialisation: the before cloud cropped to the after cloud's footprint, its x/y convex
hull buffered by the radius: the polygon a PDAL ``filters.crop`` receives too."""

from __future__ import annotations

import numpy as np

from ..core.polygons import covers
from ..core.types import SoilVolumeError, short_error

BLOCK = 1 << 14  # points the crop mask looks up at a time
MIN_COLUMNS = 30  # fewest thinned columns a cloud needs to be registered, gridded and compared


def check_spread(xy: np.ndarray, path: str, what: str = "") -> None:
    """Refuse a cloud whose (thinned) x/y are too few or on a line: nothing to register or grid."""
    if len(xy) < MIN_COLUMNS:
        raise SoilVolumeError(
            f"{path}: too few points to work with ({len(xy)} distinct positions {what}, at least {MIN_COLUMNS} needed)"
        )
    x, y = xy[:, 0] - xy[:, 0].mean(), xy[:, 1] - xy[:, 1].mean()  # two vectors, not np.cov's (2, N) copy
    xy_ = float(x @ y)
    moments = np.array([[x @ x, xy_], [xy_, y @ y]]) / len(xy)
    # the singular values of the centred points / sqrt(n), from their 2 x 2 second moments
    spread = np.sqrt(np.maximum(np.linalg.eigvalsh(moments)[::-1], 0.0))
    if spread[1] < max(0.01, 1e-4 * spread[0]):
        raise SoilVolumeError(f"{path}: the points lie on a line (a degenerate cloud: no area to compare)")


def footprint(xy: np.ndarray, radius: float = 0.0, segments: int = 64) -> np.ndarray:
    """Convex hull of ``xy`` buffered by ``radius`` (a Minkowski sum with a circumscribed
    ``segments``-gon), (K, 2) vertices counter-clockwise, not closed; the hull itself when ``radius`` <= 0."""
    verts = _hull(xy)
    if radius <= 0:
        return verts
    from scipy.spatial import ConvexHull

    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    r = radius / np.cos(np.pi / segments)
    circle = np.c_[np.cos(ang), np.sin(ang)] * r
    pts = (verts[:, None, :] + circle[None, :, :]).reshape(-1, 2)
    return pts[ConvexHull(pts).vertices]


def _hull(xy: np.ndarray) -> np.ndarray:
    """The convex hull's vertices of ``xy`` (of every k-th point past 200 000 points)."""
    from scipy.spatial import ConvexHull, QhullError  # here: a Dask worker masks with a footprint, never makes one

    pts = xy[:: max(1, len(xy) // 200_000)]
    idx = _not_inside_extremes(pts)
    try:
        hull = ConvexHull(pts[idx])
    except (QhullError, ValueError) as exc:
        raise SoilVolumeError(f"a cloud's footprint is degenerate (points on a line?): {short_error(exc, 80)}") from exc
    return pts[idx[hull.vertices]]


def _not_inside_extremes(xy: np.ndarray) -> np.ndarray:
    """Indices of the points not well inside the octagon of the extremes in x, y, x + y and x - y
    (Akl-Toussaint): Qhull gives the same hull on them, a fraction (1e-9 of the extent kept)."""
    if len(xy) < 64:
        return np.arange(len(xy))
    x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])  # strided: 2x slower
    s, d = x + y, x - y
    order = (np.argmin(x), np.argmin(s), np.argmin(y), np.argmax(d))
    order += (np.argmax(x), np.argmax(s), np.argmax(y), np.argmin(d))
    corners = xy[[int(i) for i in order]]  # counter-clockwise round the hull
    tol = 1e-9 * float(np.max(corners.max(axis=0) - corners.min(axis=0)))
    keep = np.zeros(len(xy), bool)
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        if (a == b).all():  # one point extreme in two directions: no edge
            continue
        (ex, ey), left = b - a, np.multiply(y, b[0] - a[0])
        left -= ey * x  # |edge| x the distance left of the edge, plus the constant below
        keep |= left <= ex * a[1] - ey * a[0] + tol * float(np.hypot(ex, ey))
    return np.flatnonzero(keep)


class PolygonMask:
    """Point-in-polygon for streaming: the polygon rasterized on about ``max_cells`` cells at most, of
    ``resolution`` m at least (a cell is in when its centre is)."""

    def __init__(self, polygon: np.ndarray, resolution: float = 0.5, max_cells: int = 4_000_000) -> None:
        self.lo = polygon.min(axis=0)
        span = polygon.max(axis=0) - self.lo
        self.res = max(resolution, float(np.sqrt(span[0] * span[1] / max_cells)))
        cols, rows = (np.ceil(span / self.res).astype(int) + 1).tolist()
        xs = self.lo[0] + (np.arange(cols) + 0.5) * self.res
        ys = self.lo[1] + (np.arange(rows) + 0.5) * self.res
        gx, gy = np.meshgrid(xs, ys)
        self.mask = covers([polygon], gx.ravel(), gy.ravel()).reshape(rows, cols)  # boundary in, as filters.crop
        self.framed = np.pad(self.mask, 1)  # a border of False: indices clipped onto it are out

    def __call__(self, xyz: np.ndarray) -> np.ndarray:
        """Whether each point falls in a cell of the mask, block by block (temporaries in the cache)."""
        n = len(xyz)
        out = np.empty(n, bool)
        flat = self.framed.ravel()
        scratch = np.empty(min(n, BLOCK)), np.empty(min(n, BLOCK), np.int64), np.empty(min(n, BLOCK), np.int64)
        for start in range(0, n, BLOCK):
            stop = min(n, start + BLOCK)
            t, col, row = (a[: stop - start] for a in scratch)
            self._cell(xyz[start:stop, 0], 0, t, col)
            self._cell(xyz[start:stop, 1], 1, t, row)
            row += 1  # the flat index of (row + 1, col + 1) in the framed mask
            row *= self.framed.shape[1]
            row += col
            row += 1
            flat.take(row, out=out[start:stop])
        return out

    def key(self) -> str:
        """A digest of the lattice (its corner, cell and cells): masks of the same polygon share it."""
        import hashlib

        head = np.r_[self.lo, self.res, self.mask.shape].astype(float).tobytes()
        return hashlib.sha1(head + np.packbits(self.mask).tobytes(), usedforsecurity=False).hexdigest()

    def _cell(self, v: np.ndarray, axis: int, t: np.ndarray, out: np.ndarray) -> None:
        """``int((v - lo) / res)`` along ``axis`` clipped to -1..n (the frame) into ``out``, via ``t``."""
        np.subtract(v, self.lo[axis], out=t)
        t /= self.res
        np.copyto(out, t, casting="unsafe")  # as astype(np.int64)
        np.clip(out, -1, self.mask.shape[1 - axis], out=out)


def polygon_wkt(polygon: np.ndarray, origin: np.ndarray | None = None) -> str:
    """WKT of a polygon, shifted by ``origin`` (local -> absolute coordinates)."""
    p = polygon + (0 if origin is None else np.asarray(origin)[:2])
    ring = np.vstack([p, p[:1]])
    return "POLYGON ((" + ", ".join(f"{x:.3f} {y:.3f}" for x, y in ring) + "))"


def polygon_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
