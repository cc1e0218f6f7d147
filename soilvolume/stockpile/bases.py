"""The base surfaces a pile is measured from, at cell centres: a triangulation of the toe
heights (linear between toe points, the common practice), their least-squares plane, their
lowest, length-weighted average or highest level, a given elevation or a given surface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from .coverage import Window
from .toe import Toe
from .types import TOE_BASES, Base, PileError

BLOCK = 2_000_000  # (point, triangle) pairs tested at once


def toe_base(kind: str, toe: Toe, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The toe base ``kind`` (one of :data:`TOE_BASES`) at points ``x``, ``y`` (local)."""
    if kind == "triangulated":
        return triangulated(toe, x, y)
    if kind == "plane":
        a, b, c = toe.plane()
        return a + b * x + c * y
    if kind in ("lowest", "highest"):
        return np.full(x.shape, float(level_heights(toe)[0][extreme(kind, toe)]))
    if kind == "average":
        return np.full(x.shape, toe.mean())
    raise PileError(f"base '{kind}': not a toe base ({', '.join(TOE_BASES)})")


def level_heights(toe: Toe) -> tuple[np.ndarray, np.ndarray]:
    """(heights, gain) the lowest and highest levels are taken from: the toe's plane plus each
    toe height's departure ``r`` from it shrunk by the non-negative garrote ``r - t^2 / r`` at the
    universal threshold ``t = sigma sqrt(2 ln n)`` (0 within it: noise, else kept, less and less
    shrunk); ``gain`` is the garrote's slope (0 or ``1 + t^2 / r^2``). The extreme of many noisy
    heights lies beyond the true extreme by about 2 sigma; departures the noise cannot make are kept."""
    a, b, c = toe.plane()
    plane = a + b * toe.x + c * toe.y
    r = toe.z - plane
    t2 = toe.sigma**2 * 2 * np.log(max(len(toe.z), 2))
    kept = r * r > t2
    with np.errstate(divide="ignore", invalid="ignore"):
        shrunk = np.where(kept, r - t2 / r, 0.0)
        gain = np.where(kept, 1 + t2 / (r * r), 0.0)
    return plane + shrunk, gain


def extreme(kind: str, toe: Toe) -> int:
    """The toe point whose :func:`level_heights` is the ``lowest`` or ``highest``."""
    z = level_heights(toe)[0]
    return int(np.argmin(z) if kind == "lowest" else np.argmax(z))


@dataclass(frozen=True)
class Tin:
    """Where points fall in the scipy.spatial.Delaunay triangulation of the toe points: for each point, its
    triangle's three toe points ``corners`` (points, 3) and its barycentric ``weights`` (points,
    3); ``inside`` False for points outside the triangulation."""

    corners: np.ndarray
    weights: np.ndarray
    inside: np.ndarray


def tin_at(toe: Toe, x: np.ndarray, y: np.ndarray) -> Tin:
    """The :class:`Tin` of the toe points at points ``x``, ``y`` (flattened): each point's
    barycentric coordinates in every triangle at once, in blocks (scipy's ``find_simplex`` walk
    crawls over a toe's long thin triangles)."""
    tri = scipy.spatial.Delaunay(np.column_stack([toe.x, toe.y]))
    t = _transforms(tri.points[tri.simplices])
    pts = np.column_stack([np.ravel(x), np.ravel(y)])
    found = np.full(len(pts), -1)
    weights = np.zeros((len(pts), 3))
    step = max(1, BLOCK // max(1, len(t)))
    for i in range(0, len(pts), step):
        b = np.einsum("tij,ptj->pti", t[:, :2], pts[i : i + step, None, :] - t[None, :, 2])
        bary = np.concatenate([b, 1 - b.sum(axis=2, keepdims=True)], axis=2)
        hit = np.all(bary >= -1e-9, axis=2)  # NaN (a flat triangle) is no hit
        first = np.argmax(hit, axis=1)
        rows = np.arange(len(first))
        found[i : i + step] = np.where(hit[rows, first], first, -1)
        weights[i : i + step] = bary[rows, first]
    return Tin(tri.simplices[np.maximum(found, 0)], weights, found >= 0)


def _transforms(corners: np.ndarray) -> np.ndarray:
    """Each triangle's (3, 2) barycentric transform as scipy's ``scipy.spatial.Delaunay.transform`` holds it
    (the inverse of its edge matrix, then its third corner), NaN for a flat triangle; computed
    directly: scipy's takes seconds over a toe's near-flat triangles."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    m00, m01 = a[:, 0] - c[:, 0], b[:, 0] - c[:, 0]
    m10, m11 = a[:, 1] - c[:, 1], b[:, 1] - c[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        det = m00 * m11 - m01 * m10
        det = np.where(np.abs(det) > 1e-12 * (m00 * m00 + m11 * m11 + m01 * m01 + m10 * m10), det, np.nan)
        inv = np.stack([np.stack([m11, -m01], axis=1), np.stack([-m10, m00], axis=1)], axis=1) / det[:, None, None]
    return np.concatenate([inv, c[:, None, :]], axis=1)


def triangulated(toe: Toe, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The toe heights' scipy.spatial.Delaunay triangulation, linear in each triangle, at ``x``, ``y``; points
    outside it (centres of cells the boundary crosses) take the toe's plane."""
    tin = tin_at(toe, x, y)
    z = np.sum(tin.weights * toe.z[tin.corners], axis=1)
    if not tin.inside.all():
        a, b, c = toe.plane()
        xs, ys = np.ravel(x)[~tin.inside], np.ravel(y)[~tin.inside]
        z[~tin.inside] = a + b * xs + c * ys
    return z.reshape(np.shape(x))


def base_heights(base: Base, toe: Toe, window: Window) -> np.ndarray:
    """``base`` at the centres of ``window``'s cells (NaN where a surface base has no height)."""
    if base.kind == "elevation":
        return np.full(window.x.shape, float(base.z))
    if base.kind == "surface":
        return np.asarray(window.of(base.surface), dtype=np.float64)
    return toe_base(base.kind, toe, window.x, window.y)


def check_surface(base: Base, shape: tuple[int, int]) -> None:
    """A surface base must be an array of the survey grid's shape."""
    if base.kind == "surface" and (base.surface is None or base.surface.shape != shape):
        got = "none" if base.surface is None else "x".join(map(str, base.surface.shape))
        raise PileError(f"base surface: {got} cells, the survey's grid is {shape[0]}x{shape[1]}")
