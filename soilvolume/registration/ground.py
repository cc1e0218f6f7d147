"""The ground a registration is judged and refined on: point spacing, the after survey's margin
band, its points on stable ground at a pose."""

from __future__ import annotations

import numpy as np

from ..compensation.stable import find_stable, margin
from ..core.cells import bounds, cell_index, rows
from ..dem.grid import average_height, make_grid
from ..inputs.footprint import footprint, polygon_area
from . import columns
from .rigid import transform_points


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


def stable_source(
    source_xyz: np.ndarray,
    target_xyz: columns.Target,
    t: np.ndarray,
    cell: float = 1.0,
    gap: float | None = None,
) -> np.ndarray:
    """The source at ``t`` on stable ground only, its degree-2 deformation removed (both from
    :mod:`soilvolume.compensation.stable` on median grids): what the last ICP levels should see."""
    src = transform_points(source_xyz, t)
    target = target_xyz if isinstance(target_xyz, columns.Cloud) else columns.Cloud(target_xyz)
    cell = max(cell, 1.5 * (spacing(target.xyz) if gap is None else gap))  # gap: the target's spacing
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
