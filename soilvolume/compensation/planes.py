"""Plane-offset compensation as in the paper: a RANSAC plane in each registered cloud and
``d_i`` = the vertical distance between the two planes at each grid cell centre."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.types import GridSpec, SoilVolumeError

ITERATIONS, SAMPLE = 500, 20_000


@dataclass(frozen=True)
class Plane:
    """z = a*x + b*y + c in local coordinates; ``inliers`` is the inlier fraction."""

    a: float
    b: float
    c: float
    inliers: float

    def z(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.a * x + self.b * y + self.c

    def as_dict(self, origin: np.ndarray) -> dict:
        """Coefficients in absolute coordinates: z = a*X + b*Y + c."""
        c_abs = self.c + origin[2] - self.a * origin[0] - self.b * origin[1]
        return {"a": self.a, "b": self.b, "c": float(c_abs), "inlier_fraction": self.inliers}


def ransac_plane(xyz: np.ndarray, threshold: float = 0.15, seed: int = 0) -> Plane:
    """Seeded RANSAC plane (:data:`ITERATIONS` 3-point hypotheses on a subsample of :data:`SAMPLE`
    points), refined by least squares on its inliers."""
    if len(xyz) < 3:
        raise SoilVolumeError("a RANSAC plane needs at least 3 points")
    rng = np.random.default_rng(seed)
    pts = xyz[rng.choice(len(xyz), min(SAMPLE, len(xyz)), replace=False)]
    tri = pts[rng.integers(0, len(pts), size=(ITERATIONS, 3))]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    ok = norm > 1e-9
    normal, tri = normal[ok] / norm[ok, None], tri[ok]
    d = -np.einsum("ij,ij->i", normal, tri[:, 0])
    assert len(normal)
    j = int(np.argmax(_inlier_counts(pts, normal, d, threshold)))  # the first best hypothesis
    inl = np.abs(pts @ normal[j] + d[j]) < threshold
    q = pts[inl]  # refined by least squares
    coef, *_ = np.linalg.lstsq(np.c_[q[:, 0], q[:, 1], np.ones(len(q))], q[:, 2], rcond=None)
    return Plane(float(coef[0]), float(coef[1]), float(coef[2]), float(inl.mean()))


def _inlier_counts(pts: np.ndarray, normal: np.ndarray, d: np.ndarray, threshold: float) -> np.ndarray:
    """Points of ``pts`` within ``threshold`` of each plane ``normal . p + d = 0``, in blocks of 8 (in
    cache), the bits of products by blocks of 64 (any block of 2+ sums alike); a lone normal in the
    last block of 64 went through a matrix-vector product: it is scored as it was."""
    pts_t = np.ascontiguousarray(pts.T)
    n = len(normal)
    lone = 1 if n % 64 == 1 else 0
    edges = list(range(0, n - lone, 8)) + [n - lone]
    if len(edges) > 2 and edges[-1] - edges[-2] == 1:  # no block of one: it would round otherwise
        del edges[-2]
    counts = np.empty(n, np.int64)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        v = normal[a:b] @ pts_t
        v += d[a:b, None]
        counts[a:b] = np.count_nonzero(np.abs(v, out=v) < threshold, axis=1)
    if lone:
        counts[-1] = int((np.abs(pts @ normal[-1:].T + d[-1:]) < threshold).sum())
    return counts


def plane_offset(before: Plane, after: Plane, grid: GridSpec) -> np.ndarray:
    """``d_i``: after-plane minus before-plane height at every cell centre (rows, cols)."""
    x, y = grid.centers_local()
    return after.z(x, y) - before.z(x, y)
