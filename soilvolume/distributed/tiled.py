"""The distributed engine: the same method as the in-process run, with the point work done as
Dask tasks, so no process holds a survey's points.

1. A first pass of tasks (:mod:`scan`) returns column-thinning sums, counts and chunk boxes;
   registration runs in the driver on the thinned subsets, as in-process.
2. The shared grid is cut into tiles; each task streams only what meets its tile (VPC tiles, COPC
   nodes, the chunks of a plain file whose boxes the first pass recorded), assigns points to the
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
from pathlib import Path

import numpy as np

from ..core.hooks import Hooks, Result
from ..core.outputs import OutputDir
from ..core.types import GridSpec, SoilVolumeError
from ..dem.grid import choose_cell
from ..inputs.footprint import footprint, inside, polygon_area
from ..inputs.prepare import Prepared, prepare
from ..inputs.stream import open_source
from ..options import Options
from ..registration.rigid import transform_points
from ..reporting.report import build_report, write_json
from ..workflow.steps import (
    add_quality,
    correction_step,
    planes_and_volumes,
    register_pair,
    shared_grid,
    write_report_html,
)
from .cluster import checker
from .cog import write_outputs
from .fingerprint import run_parts
from .scan import dask_loader
from .schedule import Schedule, check_tiles, client, worker_gb
from .tilestore import run_store
from .tiletask import MAX_TILE, MIN_TILE, TILE_BYTES_PER_POINT, Plan, epoch_dems, plan_parts, run_tiles, tiles


def data_tile_m(src, cell: float, side: int) -> float | None:
    """The side (m) of a VPC's square tiles when a grid tile can hold one (else None)."""
    if src.vpc is None or len(src.vpc.tiles) < 2:
        return None
    widths = [t.hi[0] - t.lo[0] for t in src.vpc.tiles]
    size = float(np.median(widths))
    return size if 0 < size / cell <= side else None


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


def cell_from_columns(prep: Prepared, after_thin: np.ndarray, minimum: float = 0.5) -> float:
    """:func:`grid.cell_for` from the thinned subset: the before points behind the column
    centroids inside the registered after footprint, over the footprint's area."""
    poly = footprint(after_thin[:, :2])
    ins = inside(prep.before_thin[:, :2], poly)
    return choose_cell(int(prep.before_counts[ins].sum()), polygon_area(poly), minimum=minimum)


def schedule_for(before, after, options: Options, pipeline: bool) -> Schedule:
    """The schedule of a run: ``--scheduler``, or for ``auto`` in-process when the pair's points
    (from the LAS/COPC/VPC headers) fit the memory budget; pipelines and other formats run
    in-process."""
    from .schedule import choose, parse

    if options.scheduler == "auto":
        points = [_header_points(p) for p in (before, after)]
        if pipeline or None in points:
            return Schedule("none")
        return choose("auto", options.memory_limit, sum(points))
    chosen = parse(options.scheduler)
    if pipeline and chosen.kind != "none":
        raise SoilVolumeError(
            f"--scheduler {options.scheduler}: preparation pipelines run in-process only (use --scheduler none)"
        )
    return chosen


def _header_points(path) -> int | None:
    """A LAS/LAZ/COPC file's or a VPC's point count from its header(s); None for other formats."""

    from ..inputs.io import LAS_SUFFIXES

    suffix = Path(path).suffix.lower()
    if suffix not in LAS_SUFFIXES | {".vpc"}:
        return None
    return open_source(path).count


def estimate_tiled(before, after, out: OutputDir, options: Options, timer, hooks: Hooks, schedule: Schedule) -> Result:
    """the in-process run (:mod:`soilvolume.workflow.estimate`) with the point work as Dask tasks on ``schedule``."""
    if options.ground in ("filter", "csf"):
        raise SoilVolumeError(
            f"--ground {options.ground} needs whole clouds: use --scheduler none (or classify the tiles first)"
        )
    hooks.step(2, f"reading {before.name} and {after.name} (thinning for registration)")
    with run_store(out.final) as store, client(schedule, options.memory_limit, store.scratch) as starting:
        return _tiled(before, after, out, options, timer, hooks, schedule, (starting, store))


def _tiled(before, after, out: OutputDir, options: Options, timer, hooks: Hooks, schedule: Schedule, started) -> Result:
    """The tiled run, with ``started`` = (the :class:`cluster.Starting` client, the run's
    :class:`tilestore.RunStore`)."""
    starting, store = started
    with timer("cluster_wait"):
        c = starting.result(checker(hooks))
    with timer("crop"):  # the registration subsets: a first pass as Dask tasks
        src_b, src_a = open_source(before), open_source(after)
        prep = prepare(
            src_b,
            src_a,
            options,
            check=lambda: hooks.step(5, "reading"),
            full=False,
            loader=dask_loader(c, lambda m: hooks.step(8, m), checker(hooks)),
        )
    reg, options = register_pair(prep, options, hooks, timer)
    after_thin = transform_points(prep.after_thin, reg.transform)
    cell = options.cell if options.cell else cell_from_columns(prep, after_thin)
    grid = shared_grid(prep, after_thin, options.with_(cell=cell))
    plan = Plan(
        str(before),
        str(after),
        prep.inputs["before"]["crs_wkt"],
        prep.inputs["after"]["crs_wkt"],
        prep.frame,
        prep.origin,
        grid,
        reg.transform,
        prep.ground,
        footprint(prep.after_thin[:, :2], options.radius),
        options.statistic,
        prep.index,
        prep.rules,
    )
    task_gb, density = worker_gb(schedule, options.memory_limit), points_per_cell(prep, cell)
    side = tile_side(options, grid, density, task_gb, schedule.workers)
    align = None if options.tile_cells else data_tile_m(src_b, cell, 2 * side)
    if align and not fits(density * (align / cell) ** 2, task_gb):
        align = None  # a data tile too dense for one task's memory: smaller tiles, read more than once
    if align:  # snap to the input's tiles: rounded tile widths in metres to whole cells
        side = max(1, round(align / cell))
    windows = tiles(grid, side, align)
    check_tiles(windows, density, task_gb, options)
    hooks.step(55, f"gridding {len(windows)} tiles of {side} x {side} cells on {schedule}")
    k = volume_factor(options, grid, schedule)
    said = store.bind(run_parts(before, after, options, plan_parts(plan, windows, k)))
    if said:
        hooks.step(55, said)
    tiles_kept = store.tiles(windows)
    if k > 1:
        from .volumestep import tiled_volume_step

        report, stats, html = tiled_volume_step(
            c, plan, tiles_kept, k, (prep, reg, after_thin), out, options, timer, hooks
        )
    else:
        with timer("grids"):
            dem_a, dem_b = epoch_dems(run_tiles(c, plan, windows, hooks, tiles_kept, stats := {}), plan.rules)
        hooks.step(70, correction_step(options))
        vols, p_b, p_a = planes_and_volumes(prep, reg, grid, dem_a, dem_b, after_thin, options, timer, hooks)
        hooks.step(85, "writing outputs (COG)")
        with timer("write"):
            arrays = {"dem_b": vols.dem_b, "dem_a": vols.dem_a}
            arrays.update(diff=vols.diff, offset=vols.offset, filled_mask=vols.filled_mask, classes=vols.classes)
            write_outputs(out, lambda key, r, c: arrays[key][r, c], grid, float(prep.origin[2]), options.correction)
        with timer("report"):
            report = build_report(prep, reg, grid, vols, p_b, p_a, options, timer)
            add_quality(report, vols, grid, options, hooks)
    report["engine"] = {
        "scheduler": str(schedule),
        "tiles": len(windows),
        "tile_cells": side,
        "points_per_cell": round(density, 3),
        "volume_step": "whole grid" if k == 1 else f"tiles, overview of {k} x {k} cells",
        "tiles_resumed": stats["resumed"],
        "kept_tiles_discarded": said,
        "task_points_read": stats["read"],
        "task_seconds": round(stats["seconds"], 3),
        "points_per_task_second": round(stats["read"] / max(stats["seconds"], 1e-9)),
    }
    with timer("report"):
        write_json(out.path("report.json"), report)
        if k == 1:
            html = (vols, grid, dem_a.heights + prep.origin[2])
        write_report_html(out, report, *html)
    return Result(report)


def volume_factor(options: Options, grid: GridSpec, schedule: Schedule) -> int:
    """1 for the volume step on the whole grid in the driver, else the block side of the
    overview the tiled volume step finds the correction on (``--volume-step``)."""
    from .overview import MAX_CELLS, blocks_for, factor
    from .schedule import budget_gb

    k = factor(grid, budget_gb(options.memory_limit))
    if options.volume_step == "whole" or (options.volume_step == "auto" and k == 1):
        return 1
    return max(k, 2, blocks_for(grid, MAX_CELLS))  # the overview's volume step stays short
