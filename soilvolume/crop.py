"""Alignment initialisation: crop the before cloud to the after cloud's footprint plus a radius.

The footprint is the convex hull of the after cloud's x/y (its GPS position), buffered by the
radius; the same polygon is what a PDAL ``filters.crop`` receives, so both paths agree.
"""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path as MplPath
from scipy.spatial import ConvexHull, QhullError

from .types import SoilVolumeError


def footprint(xy: np.ndarray, radius: float = 0.0, segments: int = 64) -> np.ndarray:
    """Convex hull of ``xy`` buffered by ``radius`` (exact Minkowski sum with a 'segments'-gon
    circumscribing the circle), as a closed-free (K, 2) vertex array, counter-clockwise."""
    step = max(1, len(xy) // 200_000)
    try:
        hull = ConvexHull(xy[::step])
    except (QhullError, ValueError) as exc:
        raise SoilVolumeError(f"the after cloud's footprint is degenerate (collinear points?): {exc}") from exc
    verts = xy[::step][hull.vertices]
    if radius > 0:
        ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        r = radius / np.cos(np.pi / segments)
        circle = np.c_[np.cos(ang), np.sin(ang)] * r
        pts = (verts[:, None, :] + circle[None, :, :]).reshape(-1, 2)
        verts = pts[ConvexHull(pts).vertices]
    return verts


def inside(xy: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Boolean mask of points inside a polygon (vertices (K, 2))."""
    return MplPath(polygon).contains_points(xy)


def polygon_wkt(polygon: np.ndarray, origin: np.ndarray | None = None) -> str:
    """WKT of a polygon, shifted by ``origin`` (local -> absolute coordinates)."""
    p = polygon + (0 if origin is None else np.asarray(origin)[:2])
    ring = np.vstack([p, p[:1]])
    return "POLYGON ((" + ", ".join(f"{x:.3f} {y:.3f}" for x, y in ring) + "))"


def polygon_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def crop_mask(before_xy: np.ndarray, after_xy: np.ndarray, radius: float) -> np.ndarray:
    """Mask of before points within ``radius`` of the after cloud's footprint (bbox prefilter)."""
    poly = footprint(after_xy, radius)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    box = ((before_xy >= lo) & (before_xy <= hi)).all(axis=1)
    mask = np.zeros(len(before_xy), dtype=bool)
    idx = np.flatnonzero(box)
    mask[idx] = inside(before_xy[idx], poly)
    return mask
