"""Robust point-to-plane ICP (Tukey kernel) over numpy arrays, computed as Open3D's
``registration_icp`` with ``TransformationEstimationPointToPlane(TukeyLoss(k))`` computes it:
the nearest target point within the correspondence distance, a Gauss-Newton step of the
weighted point-to-plane residuals, the step applied to the moved source, stop when neither
fitness nor inlier RMSE changes by the tolerance. Poses agree with Open3D's to ~1e-14.

Without Open3D's ~0.4-0.6 s import, and faster: an iteration moves the points by millimetres,
so the nearest neighbours found are kept while a bound proves them unchanged (:class:`Nearest`),
and only the others are searched again: on the native kernel's bucket grid (:class:`GridIndex`),
else SciPy's k-d tree, the same neighbours either way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..native import kernels

SLACK = 1.5  # the searches look this many correspondence distances far: room to move in
THREADED = 4096  # fewest points searched on several threads
DET_MIN = 1e-6  # a normal matrix with a smaller determinant gives no step (as Open3D)
CYCLE = 1e-12  # a pose closer than this to one a few iterations before: ICP goes round a cycle of poses
PERIODS = range(2, 9)  # the cycles looked for: ICP on gentle terrain can go round 2, 4 or 8 poses


@dataclass(frozen=True)
class IcpResult:
    """The transform (source -> target), the fraction of source points with a correspondence
    and the RMS of their point-to-point distances, at the last iteration."""

    transform: np.ndarray
    fitness: float
    inlier_rmse: float
    iterations: int


def tree_of(target: np.ndarray) -> cKDTree | GridIndex:
    """What :class:`Nearest` searches a target (N, 3) with: a :class:`GridIndex` on the native
    kernel when it is there, else SciPy's k-d tree (the same neighbours)."""
    lib = kernels()
    if lib is not None and len(target):
        return GridIndex(lib, target)
    return cKDTree(target, balanced_tree=False)


class GridIndex:
    """A target's points counted into a grid of x/y cells (``sv_grid_build``): the nearest and
    second-nearest target of each point within a bound, searched ring by ring of cells round
    the point's (``sv_grid_nearest2``), as ``cKDTree.query(k=2, distance_upper_bound=...)``
    finds them, distances summed in its order. A registration's targets are column surfaces,
    about one point per cell: building it is one counting pass, a search a few cells."""

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
        """(index of the nearest target, M for none nearer than ``bound``; distance to the second
        nearest, ``bound`` for none) of each of the (3, N) C-contiguous float64 ``points``."""
        n = points.shape[1]
        idx, second = np.empty(n, np.int64), np.empty(n)
        self.lib.sv_grid_nearest2(
            points.ctypes.data, n, self.t.ctypes.data, self.m, self.m, self.x0, self.y0, self.g, self.nx, self.ny,
            self.start.ctypes.data, self.order.ctypes.data, float(bound), idx.ctypes.data, second.ctypes.data,
        )  # fmt: skip
        return idx, second


@dataclass
class _Found:
    """What the searches found for each point: where it was searched from (3, N), its nearest
    target (M, the one at infinity, for none within the bound) and the second-nearest distance
    (at most the bound)."""

    at: np.ndarray
    index: np.ndarray
    second: np.ndarray

    def copy(self) -> _Found:
        return _Found(self.at.copy(), self.index.copy(), self.second.copy())

    def take(self, idx: np.ndarray) -> _Found:
        return _Found(np.take(self.at, idx, axis=1), self.index[idx], self.second[idx])

    def put(self, idx: np.ndarray, other: _Found) -> None:
        self.at[:, idx], self.index[idx], self.second[idx] = other.at, other.index, other.second


class Nearest:
    """The nearest target point of each source point, for a source that moves a little between
    calls: exact wherever it is within ``dist`` (a point proven farther from every target gets
    none). Each k-d tree search looks ``SLACK * dist`` far and keeps the nearest and the
    second-nearest distance; at the next call a point whose old nearest is still closer than the
    second nearest can now be (that distance less how far the point moved) keeps it, and so does
    a point with none that cannot have come within ``dist``; the others are searched again. The
    two latest searches of each point are kept (ICP can swing between two poses).
    ``workers``: the k-d tree's threads (-1: all cores); ``tree``: :func:`tree_of` the target,
    when another distance searched it already."""

    def __init__(
        self, target: np.ndarray, dist: float, workers: int = -1, tree: cKDTree | GridIndex | None = None
    ) -> None:
        self.target = np.full((3, len(target) + 1), np.inf)  # (3, M) and a target at infinity
        self.target[:, :-1] = target.T
        self.m = len(target)
        self.dist, self.bound, self.workers = dist, SLACK * dist, workers
        self.tree = tree_of(target) if tree is None else tree
        self.last: _Found | None = None
        self.older: _Found | None = None

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of each point's nearest target ((3, N) points; inf and M where
        none is within ``dist``)."""
        if self.last is None or len(self.last.index) != points.shape[1]:
            self.last, self.older = self._search(points), None
            return self._distances(self.last, points), self.last.index
        lib = kernels()
        if lib is not None and points.flags.c_contiguous and points.dtype == np.float64:
            return self._native(lib, points)
        d, ok = self._proven(self.last, points)
        idx = np.flatnonzero(~ok)
        if len(idx) and self.older is not None:
            pts = np.take(points, idx, axis=1)
            back = self.older.take(idx)
            d_back, ok = self._proven(back, pts)
            swap = idx[ok]
            ahead = self.last.take(swap)
            self.last.put(swap, back.take(np.flatnonzero(ok)))
            self.older.put(swap, ahead)
            d[swap] = d_back[ok]
            idx = idx[~ok]
        if len(idx):
            if self.older is None:
                self.older = self.last.copy()
            else:
                self.older.put(idx, self.last.take(idx))
            pts = np.take(points, idx, axis=1)
            found = self._search(pts)
            self.last.put(idx, found)
            d[idx] = self._distances(found, pts)
        return d, self.last.index

    def _native(self, lib, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`__call__` with the kept neighbours proven, swapped and set aside by the native
        kernel (``sv_nearest_kept``), the rest searched here: the same distances and state."""
        n, last = points.shape[1], self.last
        old = self.older if self.older is not None else last
        d, todo = np.empty(n), np.empty(n, np.int64)
        kept = (last.at, last.index, last.second, old.at, old.index, old.second)
        k = lib.sv_nearest_kept(
            points.ctypes.data,
            n,
            *(a.ctypes.data for a in kept),
            int(self.older is not None),
            self.target.ctypes.data,
            self.target.shape[1],
            self.m,
            self.bound - self.dist,
            d.ctypes.data,
            todo.ctypes.data,
        )
        if k:
            idx = todo[:k]
            if self.older is None:
                self.older = last.copy()
            pts = np.take(points, idx, axis=1)
            found = self._search(pts)
            last.put(idx, found)
            d[idx] = self._distances(found, pts)
        return d, last.index

    def _proven(self, found: _Found, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The distance to each point's found nearest, and whether that is still its nearest
        (or, for none, whether none can be within ``dist``)."""
        d = self._distances(found, points)
        moved = _norms(points - found.at)
        moved += 1e-9  # rounding room: a kept neighbour is proven, never assumed
        has = found.index < self.m
        return d, np.where(has, d + moved < found.second, moved < self.bound - self.dist)

    def _search(self, points: np.ndarray) -> _Found:
        if isinstance(self.tree, GridIndex):
            points = np.ascontiguousarray(points, dtype=np.float64)
            idx, second = self.tree.nearest2(points, self.bound)
            return _Found(points.copy(), idx, second)
        workers = self.workers if points.shape[1] >= THREADED else 1  # threads cost more than a few searches
        d, j = self.tree.query(points.T, k=2, distance_upper_bound=self.bound, workers=workers)
        return _Found(points.copy(), j[:, 0].astype(np.int64), np.minimum(d[:, 1], self.bound))

    def _distances(self, found: _Found, points: np.ndarray) -> np.ndarray:
        return _norms(points - np.take(self.target, found.index, axis=1))


def _norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column of a (3, N) array."""
    out = v[0] * v[0]
    out += v[1] * v[1]
    out += v[2] * v[2]
    return np.sqrt(out, out=out)


def point_to_plane(
    source: np.ndarray,
    target: np.ndarray,
    normals: np.ndarray,
    dist: float,
    init: np.ndarray,
    k: float,
    tol: float = 1e-6,
    max_iter: int = 30,
    workers: int = -1,
    nearest: Nearest | None = None,
) -> IcpResult:
    """ICP of ``source`` (N, 3) onto ``target`` (M, 3) with its unit ``normals``: correspondences
    within ``dist`` m, Tukey weights of constant ``k`` m on the point-to-plane residuals, from
    ``init``; stops when fitness and inlier RMSE change by less than ``tol`` or after ``max_iter``
    steps, or once a pose repeats one a few steps before (within :data:`CYCLE`: the ICP goes
    round a cycle of :data:`PERIODS` poses till its last step) on the pose that last step would
    reach. ``nearest``: a :class:`Nearest` of this target and distance to reuse."""
    t = np.array(init, dtype=float)
    pts = np.ascontiguousarray(source.T, dtype=float)
    if not np.array_equal(t, np.eye(4)):
        pts = _moved(pts, t)
    nn = nearest or Nearest(target, dist, workers)
    nrm = np.ascontiguousarray(normals.T)
    sel, j, fit, rmse = _matches(nn, pts)
    steps, poses = 0, []
    while steps < max_iter:
        steps += 1
        step = _step(pts, sel, j, nn.target, nrm, k)
        t = step @ t
        pts = _moved(pts, step)
        sel, j, new_fit, new_rmse = _matches(nn, pts)
        converged = abs(new_fit - fit) < tol and abs(new_rmse - rmse) < tol
        fit, rmse = new_fit, new_rmse
        if converged:
            break
        poses = [*poses[-PERIODS[-1] :], (t, fit, rmse)]
        last = _cycled(poses, max_iter - steps)
        if last is not None:
            return IcpResult(*last, max_iter)
    return IcpResult(t, fit, rmse, steps)


def _cycled(poses: list[tuple], left: int) -> tuple | None:
    """The (pose, fitness, RMSE) the ICP ends on ``left`` iterations on, when the latest of
    ``poses`` (oldest first) repeats the one a period before: the poses repeat from there on;
    None when no period of :data:`PERIODS` repeats."""
    for p in PERIODS:
        if len(poses) > p and float(np.abs(poses[-1][0] - poses[-1 - p][0]).max()) < CYCLE:
            return poses[-1 - p + left % p] if left % p else poses[-1]
    return None


def _matches(nn: Nearest, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The source points with a correspondence, their targets, fitness and inlier RMSE."""
    d, j = nn(pts)
    sel = np.flatnonzero(d <= nn.dist)
    if len(sel) == 0:
        return sel, j[sel], 0.0, 0.0
    dd = d[sel]
    return sel, j[sel], len(sel) / pts.shape[1], float(np.sqrt(np.dot(dd, dd) / len(sel)))


def _step(pts: np.ndarray, sel: np.ndarray, j: np.ndarray, target: np.ndarray, nrm: np.ndarray, k: float):
    """The step (4x4) of the points ``pts[:, sel]`` on the planes of their targets ``target[:, j]``
    and normals ``nrm[:, j]``: its per-point terms by the native kernel when it is there."""
    lib = kernels()
    if lib is not None and pts.flags.c_contiguous and nrm.flags.c_contiguous and target.flags.c_contiguous:
        return _native_step(lib, pts, sel, j, target, nrm, k)
    return _numpy_step(np.take(pts, sel, axis=1), np.take(target, j, axis=1), np.take(nrm, j, axis=1), k)


def _numpy_step(p: np.ndarray, q: np.ndarray, n: np.ndarray, k: float) -> np.ndarray:
    """The Gauss-Newton step (4x4) of the Tukey-weighted point-to-plane residuals of points
    ``p`` on planes (``q``, ``n``), all (3, K): identity when there are none or the system is
    singular."""
    if p.shape[1] == 0:
        return np.eye(4)
    dq = p - q
    r = dq[0] * n[0]
    r += dq[1] * n[1]
    r += dq[2] * n[2]
    u = r / k
    u *= u
    np.subtract(1.0, u, out=u)
    u *= u
    w = np.where(np.abs(r) <= k, u, 0.0)
    jac = np.empty((6, p.shape[1]))
    jac[0] = p[1] * n[2] - p[2] * n[1]  # rows of p x n, then n
    jac[1] = p[2] * n[0] - p[0] * n[2]
    jac[2] = p[0] * n[1] - p[1] * n[0]
    jac[3:] = n
    return _solved(jac * w, jac, r)


def _solved(jw: np.ndarray, jac: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The step (4x4) of the normal equations ``jw jac^T x = -jw r`` (identity when singular)."""
    a = jw @ jac.T
    det = np.linalg.det(a)
    if not np.isfinite(det) or abs(det) < DET_MIN:
        return np.eye(4)
    return _matrix(np.linalg.solve(a, -(jw @ r)))


def _native_step(lib, pts: np.ndarray, sel: np.ndarray, j: np.ndarray, target: np.ndarray, nrm: np.ndarray, k: float):
    """:func:`_numpy_step` with its per-point terms from the native kernel (``sv_icp_terms``) and
    the same matrix products: the same step, bit for bit."""
    m = len(sel)
    if m == 0:
        return np.eye(4)
    jac, jw, r = np.empty((6, m)), np.empty((6, m)), np.empty(m)
    sel, j = np.ascontiguousarray(sel, np.int64), np.ascontiguousarray(j, np.int64)
    lib.sv_icp_terms(
        pts.ctypes.data,
        pts.shape[1],
        sel.ctypes.data,
        j.ctypes.data,
        m,
        target.ctypes.data,
        target.shape[1],
        nrm.ctypes.data,
        nrm.shape[1],
        float(k),
        jac.ctypes.data,
        jw.ctypes.data,
        r.ctypes.data,
    )
    return _solved(jw, jac, r)


def _matrix(x: np.ndarray) -> np.ndarray:
    """The 4x4 transform of a small motion (rx, ry, rz, tx, ty, tz): Rz Ry Rx, then the shift."""
    ca, sa = np.cos(x[0]), np.sin(x[0])
    cb, sb = np.cos(x[1]), np.sin(x[1])
    cc, sc = np.cos(x[2]), np.sin(x[2])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rz = np.array([[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]])
    out = np.eye(4)
    out[:3, :3] = rz @ ry @ rx
    out[:3, 3] = x[3:]
    return out


def _moved(pts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(3, N) points under a 4x4 transform."""
    out = t[:3, :3] @ pts
    out += t[:3, 3:4]
    return out
