"""Robust point-to-plane ICP (Tukey kernel) over numpy arrays, as Open3D's ``registration_icp`` with
``TransformationEstimationPointToPlane(TukeyLoss(k))`` (poses agree to ~1e-14), without its ~0.5 s
import and faster: neighbours are kept while a bound proves them (:class:`.nearest.Nearest`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..native import kernels
from .nearest import Nearest
from .rigid import rotation_zyx

DET_MIN = 1e-6  # a normal matrix with a smaller determinant gives no step (as Open3D)
CYCLE = 1e-12  # a pose closer than this to one a few iterations before: ICP goes round a cycle of poses
PERIODS = range(2, 9)  # the cycles looked for: ICP on gentle terrain can go round 2, 4 or 8 poses


@dataclass(frozen=True)
class IcpResult:
    """The transform (source -> target), fitness and inlier RMSE at the last iteration."""

    transform: np.ndarray
    fitness: float
    inlier_rmse: float
    iterations: int


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
    """ICP of ``source`` (N, 3) onto ``target`` (M, 3) with unit ``normals``: correspondences within
    ``dist``, Tukey ``k``, from ``init``; stops when fitness and RMSE change by under ``tol``, after
    ``max_iter`` steps, or on a cycle of poses (:data:`PERIODS`) at the pose its last step would reach.
    ``nearest``: a :class:`Nearest` of this target and distance to reuse."""
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
    """The (pose, fitness, RMSE) ``left`` iterations on when the latest of ``poses`` repeats the one a
    period before (None when none does)."""
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
    """The step (4x4) of ``pts[:, sel]`` on the planes of ``target[:, j]``, ``nrm[:, j]`` (native terms
    when built)."""
    lib = kernels()
    if lib is not None and pts.flags.c_contiguous and nrm.flags.c_contiguous and target.flags.c_contiguous:
        return _native_step(lib, pts, sel, j, target, nrm, k)
    return _numpy_step(np.take(pts, sel, axis=1), np.take(target, j, axis=1), np.take(nrm, j, axis=1), k)


def _numpy_step(p: np.ndarray, q: np.ndarray, n: np.ndarray, k: float) -> np.ndarray:
    """The Gauss-Newton step (4x4) of Tukey-weighted residuals of ``p`` on planes (``q``, ``n``), all
    (3, K); identity for none or a singular system."""
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
    """The step (4x4) of the normal equations ``jw jac^T x = -jw r`` (identity when singular): the small
    motion x = (rx, ry, rz, tx, ty, tz) as Rz Ry Rx, then the shift."""
    a, out = jw @ jac.T, np.eye(4)
    det = np.linalg.det(a)
    if not np.isfinite(det) or abs(det) < DET_MIN:
        return out
    x = np.linalg.solve(a, -(jw @ r))
    out[:3, :3], out[:3, 3] = rotation_zyx(*x[:3]), x[3:]
    return out


def _native_step(lib, pts: np.ndarray, sel: np.ndarray, j: np.ndarray, target: np.ndarray, nrm: np.ndarray, k: float):
    """:func:`_numpy_step` with its per-point terms from ``sv_icp_terms``: the same bits."""
    m = len(sel)
    if m == 0:
        return np.eye(4)
    jac, jw, r = np.empty((6, m)), np.empty((6, m)), np.empty(m)
    sel, j = np.ascontiguousarray(sel, np.int64), np.ascontiguousarray(j, np.int64)
    lib.sv_icp_terms(
        pts.ctypes.data, pts.shape[1], sel.ctypes.data, j.ctypes.data, m, target.ctypes.data, target.shape[1],
        nrm.ctypes.data, nrm.shape[1], float(k), jac.ctypes.data, jw.ctypes.data, r.ctypes.data,
    )  # fmt: skip
    return _solved(jw, jac, r)


def _moved(pts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(3, N) points under a 4x4 transform."""
    out = t[:3, :3] @ pts
    out += t[:3, 3:4]
    return out
