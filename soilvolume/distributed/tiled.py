"""The distributed engine's pieces (its backend: :mod:`soilvolume.execution.tiled`): the same method as the
in-process run, with the point work done as Dask tasks, so no process holds a survey's points.

1. A first pass of tasks (:mod:`scan`) returns column-thinning sums, counts and chunk boxes;
   registration runs in the driver on the thinned subsets, as in-process.
2. The shared grid is cut into tiles; each task streams only what meets its tile (VPC tiles, COPC
   nodes, the chunks of a plain file whose boxes the first pass recorded; VPC tiles the first pass
   kept on the workers, cropped and local, when they fit: :mod:`pointcache`), assigns points to the
   *global* grid's cells and computes its cells' heights with :func:`grid.cell_heights`, so a cell
   gets the same points as in-process (no halo is needed: a point belongs to one cell).
3. ``--volume-step whole``: the per-tile rasters are gathered (a few numbers per cell, against
   ~8 points per cell) and the volume step (refill, holes, correction fitted once on the whole
   grid, uncertainty, budgets) runs as in-process. ``tiles`` (grids too large for one process):
   see :mod:`volumestep`. Outputs are written block by block as COGs. Finished tiles are kept
   after an interruption, keyed by what they were computed from (:mod:`tilestore`), so the
   same command resumes.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.types import GridSpec
from ..inputs.footprint import footprint, polygon_area
from ..inputs.prepare import Prepared
from ..options import Options
from .overview import MAX_CELLS, blocks_for, factor
from .schedule import TILE_BYTES_PER_POINT, Schedule, budget_gb
from .tiletask import MAX_TILE, MIN_TILE


def data_tiling(src, cell: float, side: int) -> tuple[float, float, float] | None:
    """(pitch m, x, y of a tile corner) of a VPC's square tiling when a grid tile can hold one data
    tile (else None): the spacing and phase of the tiles' lower-left corners, snapped to ``cell``.
    Not the header boxes' widths: those span the points (49.999 m in a 50 m tiling), and windows
    cut on a 49.999 m pitch would cross every data tile, each then read by several tasks."""
    if src.vpc is None or len(src.vpc.tiles) < 2:
        return None
    lows = np.array([t.lo[:2] for t in src.vpc.tiles], float)
    steps = np.rint(lows / cell).astype(np.int64)  # corners in cells (a tile's first points sit at its corner)
    pitch = _mode(np.concatenate([np.diff(_shared(steps[:, k])) for k in (0, 1)]))
    if pitch is None or not 0 < pitch <= side:
        return None
    x0, y0 = (_mode(steps[:, k] % pitch) for k in (0, 1))
    return pitch * cell, x0 * cell, y0 * cell


def _shared(corners: np.ndarray) -> np.ndarray:
    """The distinct corner coordinates (along one axis) that at least a median number of tiles
    share: a row or column of a tiling shares its edge, an edge tile whose points start inside it
    has a coordinate of its own."""
    v, n = np.unique(corners, return_counts=True)
    return v[n >= np.median(n)]


def _mode(values: np.ndarray) -> int | None:
    """The most common of ``values`` (the smallest on ties), None when there are none."""
    if len(values) == 0:
        return None
    v, n = np.unique(values, return_counts=True)
    return int(v[np.argmax(n)])


TILE_POINTS = 32e6  # points per tile at most: ~1.3 GB per task; fewer reads of dense LAZ tiles


def fits(points: float, task_gb: float) -> bool:
    """Whether a tile of ``points`` points fits half of one task's memory."""
    return points * TILE_BYTES_PER_POINT <= 0.5 * task_gb * 2**30


def tile_side(options: Options, grid: GridSpec, points_per_cell: float, task_gb: float, workers: int) -> int:
    """Tile side (cells): ``options.tile_cells``, else what a task's memory share holds, and
    small enough for two tiles per worker."""
    if options.tile_cells > 0:
        return int(options.tile_cells)
    points = min(TILE_POINTS, task_gb * 2**30 * 0.5 / TILE_BYTES_PER_POINT)
    side = math.sqrt(points / max(points_per_cell, 1e-3))
    side = min(side, math.sqrt(grid.rows * grid.cols / (2 * max(1, workers))))
    return int(np.clip(side, MIN_TILE, MAX_TILE))


def points_per_cell(prep: Prepared, cell: float) -> float:
    """Expected points (both epochs) per grid cell: each epoch's points over its footprint."""
    area = [polygon_area(footprint(t[:, :2])) for t in (prep.before_thin, prep.after_thin)]
    used = [prep.inputs[e]["points_after_crop"] for e in ("before", "after")]
    return sum(n / max(a, 1.0) for n, a in zip(used, area, strict=True)) * cell**2


def volume_factor(options: Options, grid: GridSpec, schedule: Schedule) -> int:
    """1 for the volume step on the whole grid in the driver, else the block side of the
    overview the tiled volume step finds the correction on (``--volume-step``)."""
    k = factor(grid, budget_gb(options.memory_limit))
    if options.volume_step == "whole" or (options.volume_step == "auto" and k == 1):
        return 1
    return max(k, 2, blocks_for(grid, MAX_CELLS))  # the overview's volume step stays short
