"""The ground a registration is judged and refined on: point spacing, the after survey's margin
band, its points on stable ground at a pose; how well a pose fits: the share of after points near
the before surface, and the best of several poses judged on the margin."""

from __future__ import annotations

import numpy as np

from ..compensation.stable import find_stable, margin
from ..core.cells import bounds, cell_index, rows
from ..dem.grid import average_height, make_grid
from ..inputs.footprint import footprint, polygon_area
from . import columns
from .rigid import transform_points

EVAL_DISTANCE = 0.4


def spacing(xyz: np.ndarray) -> float:
    """Mean horizontal point spacing (m) of a cloud: sqrt(footprint area / points)."""
    return float(np.sqrt(polygon_area(footprint(xyz[:, :2])) / max(len(xyz), 1)))


def cap_voxel(xyz: np.ndarray, max_points: int) -> float:
    """The voxel size that leaves about ``max_points`` of a cloud (0 when it has fewer)."""
    if len(xyz) <= max_points:
        return 0.0
    return spacing(xyz) * float(np.sqrt(len(xyz) / max_points))


def margin_points(xyz: np.ndarray, gap: float) -> np.ndarray:
    """The points in the margin band of a cloud's own footprint (:func:`.stable.margin`): surveys
    are flown beyond the works, so it is most likely stable."""
    cell = max(1.0, 2.0 * gap)
    cols = columns.columns(xyz, cell)
    valid = np.zeros(cols.shape, bool)
    valid[cols.row, cols.col] = True
    band = margin(valid, cell)
    ix = np.clip(cell_index(xyz[:, 0], cols.lo[0], cell), 0, cols.shape[1] - 1)
    iy = np.clip(cell_index(xyz[:, 1], cols.lo[1], cell), 0, cols.shape[0] - 1)
    return rows(xyz, band[iy, ix])


def stable_source(source_xyz: np.ndarray, target_xyz: columns.Target, t: np.ndarray, gap: float) -> np.ndarray:
    """The source at ``t`` on stable ground only, its degree-2 deformation removed (both from
    :mod:`soilvolume.compensation.stable` on median grids): what the last ICP levels should see."""
    src = transform_points(source_xyz, t)
    target = target_xyz if isinstance(target_xyz, columns.Cloud) else columns.Cloud(target_xyz)
    cell = max(1.0, 1.5 * gap)  # gap: the target's spacing
    grid = make_grid(*bounds(src), cell, np.zeros(3), None)
    top = np.array([grid.xmin + (grid.cols + 1) * grid.cell, grid.ymax + grid.cell])
    near = target.within(np.array([grid.xmin - grid.cell, grid.ymax - (grid.rows + 1) * grid.cell]), top)
    diff = average_height(src, grid, "median")[0] - average_height(near, grid, "median")[0]
    if np.isfinite(diff).sum() < 20:
        return src[:0]
    stable, trend = find_stable(diff, cell)
    row, col, ok = grid.index(src)
    keep = np.zeros(len(src), bool)
    keep[ok] = stable[row[ok], col[ok]]
    out = rows(src, keep)
    out[:, 2] -= trend[row[keep], col[keep]]
    return out


def evaluate_surface(
    source_xyz: np.ndarray, target_xyz: columns.Target, t: np.ndarray, gap: float
) -> tuple[float, float]:
    """(fitness, RMSE) on terrain: the share of source points within :data:`EVAL_DISTANCE` of the target's
    tangent planes (columns of max(0.25 m, 2 spacings ``gap``)) and their RMS; meaningful on sparse clouds."""
    src = transform_points(source_xyz[:: max(1, len(source_xyz) // 100_000)], t)
    lo, hi = bounds(src, 2)
    cols = columns.columns(target_xyz, max(0.25, 2 * gap), lo - 1.0, hi + 1.0)
    if len(cols.xyz) == 0:
        return 0.0, float("nan")
    r = np.abs(columns.plane_residuals(src, cols, columns.normals(cols)))
    ok = r <= EVAL_DISTANCE
    return float(ok.sum() / max(len(src), 1)), float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else float("nan")


def judged(after_xyz: np.ndarray, gap: float) -> np.ndarray:
    """The after points a pose is judged on: the survey's margin (works fit no pose), else all."""
    ring = margin_points(after_xyz, gap)
    return ring if len(ring) >= max(500, 0.05 * len(after_xyz)) else after_xyz


def best_on(src, before_xyz, poses, gap: float) -> tuple[tuple[np.ndarray, str], tuple[float, float]]:
    """The pose the margin points fit best (the last on ties) and its (fitness, RMSE)."""
    scored = [(evaluate_surface(src, before_xyz, t, gap=gap), k) for k, (t, _) in enumerate(poses)]
    scores, k = max(scored, key=lambda s: (round(s[0][0], 2), -np.nan_to_num(s[0][1], nan=1e9), s[1]))
    return poses[k], scores
