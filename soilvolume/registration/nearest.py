"""The ICP's nearest neighbours for a source that moves a little between calls: kept while the native
kernel proves them, the others searched again on its bucket grid (else SciPy's k-d tree, same result)."""

from __future__ import annotations

import numpy as np
import scipy

from ..native import kernels

SLACK = 1.5  # the searches look this many correspondence distances far: room to move in
THREADED = 4096  # fewest points searched on several threads


def tree_of(target: np.ndarray) -> scipy.spatial.cKDTree | GridIndex:
    """A :class:`GridIndex` of a target (N, 3) when the kernel is built, else a k-d tree."""
    lib = kernels()
    if lib is not None and len(target):
        return GridIndex(lib, target)
    return scipy.spatial.cKDTree(target, balanced_tree=False)


class GridIndex:
    """A target counted into x/y cells (``sv_grid_build``), searched ring by ring for the nearest and
    second-nearest within a bound (``sv_grid_nearest2``) as ``scipy.spatial.cKDTree.query(k=2, ...)`` finds them."""

    MAX_CELLS_PER_POINT = 4  # a sparse target's grid is coarsened to this many cells a point

    def __init__(self, lib, target: np.ndarray) -> None:
        self.lib, self.t = lib, np.ascontiguousarray(target.T, dtype=np.float64)  # (3, M)
        self.m = self.t.shape[1]
        lo, hi = self.t[:2].min(axis=1), self.t[:2].max(axis=1)
        span = np.maximum(hi - lo, 1e-9)
        g = max(float(np.sqrt(span[0] * span[1] / self.m)), 1e-6)
        while (span[0] / g + 1) * (span[1] / g + 1) > self.MAX_CELLS_PER_POINT * self.m + 16:
            g *= 1.5
        self.g, self.x0, self.y0 = g, float(lo[0]), float(lo[1])
        self.nx, self.ny = int(span[0] // g) + 1, int(span[1] // g) + 1
        self.start = np.empty(self.nx * self.ny + 1, np.int64)
        self.order = np.empty(self.m, np.int64)
        lib.sv_grid_build(
            self.t.ctypes.data, self.m, self.m, self.x0, self.y0, g, self.nx, self.ny,
            self.start.ctypes.data, self.order.ctypes.data,
        )  # fmt: skip

    def nearest2(self, points: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
        """(nearest index or M, second-nearest distance or ``bound``) of (3, N) float64 ``points``."""
        n = points.shape[1]
        idx, second = np.empty(n, np.int64), np.empty(n)
        self.lib.sv_grid_nearest2(
            points.ctypes.data, n, self.t.ctypes.data, self.m, self.m, self.x0, self.y0, self.g, self.nx, self.ny,
            self.start.ctypes.data, self.order.ctypes.data, float(bound), idx.ctypes.data, second.ctypes.data,
        )  # fmt: skip
        return idx, second


class Nearest:
    """Each source point's nearest target, exact within ``dist``. A search looks ``SLACK * dist`` far
    and keeps the second-nearest distance: a point keeps its nearest while that is closer than the
    second can now be (less how far it moved); the others are searched again. The two latest
    searches are kept (ICP can swing between two poses). ``tree``: :func:`tree_of` the target."""

    def __init__(
        self, target: np.ndarray, dist: float, workers: int = -1, tree: scipy.spatial.cKDTree | GridIndex | None = None
    ) -> None:
        self.target = np.full((3, len(target) + 1), np.inf)  # (3, M) and a target at infinity
        self.target[:, :-1] = target.T
        self.m = len(target)
        self.dist, self.bound, self.workers = dist, SLACK * dist, workers
        self.tree = tree_of(target) if tree is None else tree
        # per point: where it was searched from (3, N), its nearest (M: none), the second distance
        self.last: list[np.ndarray] | None = None
        self.older: list[np.ndarray] | None = None

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of each (3, N) point's nearest target (inf and M: none within ``dist``);
        the kept neighbours are proven by the native kernel, without it every point is searched."""
        lib, n = kernels(), points.shape[1]
        kept = self.last is not None and len(self.last[1]) == n
        if lib is not None and kept and points.flags.c_contiguous and points.dtype == np.float64:
            return self._native(lib, points)
        self.last, self.older = self._search(points), None
        return self._distances(self.last, points), self.last[1]

    def _native(self, lib, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`__call__` with the kept neighbours proven by ``sv_nearest_kept``: the same state."""
        n, last = points.shape[1], self.last
        old = self.older if self.older is not None else last
        d, todo = np.empty(n), np.empty(n, np.int64)
        k = lib.sv_nearest_kept(
            points.ctypes.data, n, *(a.ctypes.data for a in (*last, *old)), int(self.older is not None),
            self.target.ctypes.data, self.target.shape[1], self.m, self.bound - self.dist, d.ctypes.data,
            todo.ctypes.data,
        )  # fmt: skip
        if k:
            idx = todo[:k]
            if self.older is None:
                self.older = [a.copy() for a in last]
            pts = np.take(points, idx, axis=1)
            found = self._search(pts)
            for a, b in zip(last, found, strict=True):
                a[..., idx] = b
            d[idx] = self._distances(found, pts)
        return d, last[1]

    def _search(self, points: np.ndarray) -> list[np.ndarray]:
        if isinstance(self.tree, GridIndex):
            points = np.ascontiguousarray(points, dtype=np.float64)
            return [points.copy(), *self.tree.nearest2(points, self.bound)]
        workers = self.workers if points.shape[1] >= THREADED else 1  # threads cost more than a few searches
        d, j = self.tree.query(points.T, k=2, distance_upper_bound=self.bound, workers=workers)
        return [points.copy(), j[:, 0].astype(np.int64), np.minimum(d[:, 1], self.bound)]

    def _distances(self, found: list[np.ndarray], points: np.ndarray) -> np.ndarray:
        v = points - np.take(self.target, found[1], axis=1)  # each column's Euclidean norm
        out = v[0] * v[0]
        out += v[1] * v[1]
        out += v[2] * v[2]
        return np.sqrt(out, out=out)
