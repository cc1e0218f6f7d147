"""How well a pose fits: the share of after points near the before surface, and the best of several
poses judged on the after survey's margin."""

from __future__ import annotations

import numpy as np

from ..core.cells import bounds
from . import columns
from .ground import margin_points, spacing
from .rigid import transform_points

EVAL_DISTANCE = 0.4


def evaluate_surface(
    source_xyz: np.ndarray,
    target_xyz: columns.Target,
    t: np.ndarray,
    distance: float = EVAL_DISTANCE,
    gap: float | None = None,
) -> tuple[float, float]:
    """(fitness, RMSE) on terrain: the share of source points within ``distance`` of the target's
    tangent planes (columns of max(0.25 m, 2 spacings)) and their RMS; meaningful on sparse clouds."""
    src = transform_points(source_xyz[:: max(1, len(source_xyz) // 100_000)], t)
    gap = spacing(columns.Cloud.points(target_xyz)) if gap is None else gap
    lo, hi = bounds(src, 2)
    cols = columns.columns(target_xyz, max(0.25, 2 * gap), lo - 1.0, hi + 1.0)
    if len(cols.xyz) == 0:
        return 0.0, float("nan")
    r = np.abs(columns.plane_residuals(src, cols, columns.normals(cols)))
    ok = r <= distance
    fit = float(ok.sum() / max(len(src), 1))
    return fit, float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else float("nan")


def judged(after_xyz: np.ndarray, gap: float) -> np.ndarray:
    """The after points a pose is judged on: the survey's margin (works fit no pose), else all."""
    ring = margin_points(after_xyz, gap)
    return ring if len(ring) >= max(500, 0.05 * len(after_xyz)) else after_xyz


def best_on(src, before_xyz, poses, gap: float) -> tuple[tuple[np.ndarray, str], tuple[float, float]]:
    """The pose the margin points fit best (the last on ties) and its (fitness, RMSE)."""
    best, best_key, scores = poses[-1], None, (float("nan"), float("nan"))
    for k, (t, label) in enumerate(poses):
        fit, rmse = evaluate_surface(src, before_xyz, t, gap=gap)
        key = (round(fit, 2), -np.nan_to_num(rmse, nan=1e9), k)
        if best_key is None or key > best_key:
            best, best_key, scores = (t, label), key, (fit, rmse)
    return best, scores
