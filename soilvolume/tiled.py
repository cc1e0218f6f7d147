"""The distributed engine: the same method as the in-process run, with the point work done tile
by tile as Dask tasks, so no process holds a survey's points.

1. Registration as in-process, on column-thinned subsets streamed once (no full-resolution copy).
2. The shared grid is cut into tiles; each task streams only what meets its tile (VPC tiles,
   COPC nodes; plain LAS/LAZ files are streamed and filtered), assigns points to the *global*
   grid's cells and computes its cells' heights with :func:`grid.cell_heights`, so a cell gets the
   same points, hence the same height, as in-process (cells need no halo: a point belongs to one).
3. The per-tile height and count rasters are gathered (4 small numbers per cell, against ~8 points
   per cell) and the raster steps (refill, holes, correction fitted once on the whole grid,
   uncertainty, budgets) run exactly as in-process; outputs are written block by block as COGs.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import planes
from .api import Hooks, Result
from .cog import write_cog
from .crop import PolygonMask, footprint, inside, polygon_area
from .crs import WorkFrame
from .grid import cell_heights, cell_ids, choose_cell
from .options import Options
from .outputs import OutputDir
from .prepare import GROUND, Prepared, _local, prepare
from .register import register, transform_points
from .report import write_json
from .scan import dask_loader
from .schedule import Schedule, client, worker_gb
from .stream import open_source
from .types import GridSpec, SoilVolumeError

TILE_BYTES_PER_POINT = 120.0  # a task's peak per point of its tile (both epochs, ids, sort keys, chunk)
MIN_TILE, MAX_TILE = 64, 4096  # tile side (cells)
TILE_ARRAYS = ("h_a", "n_a", "s_a", "h_b", "n_b", "s_b")  # what a tile task returns


@dataclass(frozen=True)
class Plan:
    """Everything a tile task needs (picklable: sent to the workers)."""

    before: str
    after: str
    crs_b: str  # WKT of each file's CRS (header or override)
    crs_a: str
    frame: WorkFrame
    origin: np.ndarray
    grid: GridSpec
    transform: np.ndarray  # after -> before, local frame
    ground: tuple[bool, bool]  # (before, after): class 2 only
    crop: np.ndarray  # the before crop polygon (local), as in-process
    statistic: str
    index: tuple = (None, None)  # (before, after): chunk boxes of single files, for bounded reads


Window = tuple[int, int, int, int]  # r0, r1, c0, c1


def grid_tile(plan: Plan, win: Window) -> tuple[Window, tuple[np.ndarray, ...], dict]:
    """(window, (h_after, n_after, spread_after, h_before, n_before, spread_before), stats) of one
    tile: both epochs' points on its cells, their heights, counts and spreads; stats: points
    read, seconds."""
    import time

    t0, stats = time.perf_counter(), {"read": 0}
    h_b, n_b, s_b = _epoch(plan, 0, win, None, PolygonMask(plan.crop), stats)
    h_a, n_a, s_a = _epoch(plan, 1, win, plan.transform, None, stats)
    stats["seconds"] = time.perf_counter() - t0
    return win, (h_a, n_a.astype(np.int32), s_a, h_b, n_b.astype(np.int32), s_b), stats


def _epoch(plan: Plan, epoch: int, win: Window, transform, keep, stats: dict):
    """Heights and counts of one epoch (0 before, 1 after) on the window's cells."""
    from dataclasses import replace

    import pyproj

    from .run import transform_points32

    path, ground = (plan.before, plan.after)[epoch], plan.ground[epoch]
    crs = pyproj.CRS.from_wkt((plan.crs_b, plan.crs_a)[epoch])
    to_local = _local(crs, plan.frame, plan.origin, path)
    src = replace(open_source(path), index=plan.index[epoch])
    box = _read_box(plan, crs, win, transform)
    if box is not None:
        src = src.within(*box)
    ids, zs = [], []
    for xyz, cls in src.chunks():
        stats["read"] += len(xyz)
        sel = cls == GROUND if ground and cls is not None else None
        if box is not None:  # the box has a margin: cells are assigned exactly below
            near = (xyz[:, 0] >= box[0][0]) & (xyz[:, 0] <= box[1][0]) & (xyz[:, 1] >= box[0][1]) & (
                xyz[:, 1] <= box[1][1])
            sel = near if sel is None else sel & near
        if sel is not None:
            xyz = xyz[sel]
        local = to_local(xyz)
        if keep is not None:
            local = local[keep(local)]
        local = local.astype(np.float32)
        if transform is not None:
            local = transform_points32(local, transform)
        i, z = _window_cells(local, plan.grid, win)
        ids.append(i)
        zs.append(z)
    shape = (win[1] - win[0], win[3] - win[2])
    z = np.concatenate(zs).astype(np.float64)  # float32 local heights, as in-process
    return cell_heights(np.concatenate(ids), z, shape, plan.statistic, spread=True)


def _window_cells(xyz32: np.ndarray, grid: GridSpec, win: Window) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell ids within the window, and heights, of the points on the window's cells of
    ``grid`` (cells assigned on the whole grid, exactly as in-process)."""
    ids, ok = cell_ids(xyz32, grid)
    row, col = np.divmod(ids, grid.cols)
    m = (row >= win[0]) & (row < win[1]) & (col >= win[2]) & (col < win[3])
    local_ids = (row[m] - win[0]) * (win[3] - win[2]) + (col[m] - win[2])
    return local_ids.astype(np.int32), xyz32[ok, 2][m]


def _read_box(plan: Plan, crs, win: Window, transform) -> tuple[np.ndarray, np.ndarray] | None:
    """The x/y box (file CRS) a tile's points can come from, for files in the frame's CRS and
    metres (else None: read everything); ``transform`` maps the file's local points to the grid."""
    from .crs import z_unit

    if not (crs.equals(plan.frame.crs) and plan.frame.xy_unit == 1.0 and z_unit(crs) == 1.0):
        return None
    g, o = plan.grid, plan.origin
    x0, x1 = g.xmin + win[2] * g.cell - o[0], g.xmin + win[3] * g.cell - o[0]
    y0, y1 = g.ymax - win[1] * g.cell - o[1], g.ymax - win[0] * g.cell - o[1]
    corners = np.array([[x, y, 0.0] for x in (x0, x1) for y in (y0, y1)])
    margin = g.cell
    if transform is not None:  # back into the file's frame: the inverse rigid transform
        r, t = transform[:3, :3], transform[:3, 3]
        corners = (corners - t) @ r
        margin += 0.02 * (x1 - x0 + y1 - y0) + 1.0  # tilt of the unknown z
    lo, hi = corners[:, :2].min(axis=0) - margin + o[:2], corners[:, :2].max(axis=0) + margin + o[:2]
    return lo, hi


def tiles(grid: GridSpec, side: int, align: float | None = None) -> list[Window]:
    """The grid cut into tiles of ``side`` x ``side`` cells (row-major); with ``align`` (metres),
    tile edges fall on absolute multiples of it (the input's own tiling: each data tile is then
    read by one task), slivers merged into their neighbours."""
    r_off = c_off = 0
    if align:
        c_off = round(((-grid.xmin) % align) / grid.cell) % side
        r_off = round((grid.ymax % align) / grid.cell) % side
    rows, cols = _edges(grid.rows, r_off, side), _edges(grid.cols, c_off, side)
    return [(r0, r1, c0, c1) for r0, r1 in zip(rows, rows[1:], strict=False)
            for c0, c1 in zip(cols, cols[1:], strict=False)]


def _edges(n: int, offset: int, side: int) -> list[int]:
    """0, offset, offset + side, ..., n, without edges closer than side / 4 to the next."""
    inner = [e for e in range(offset, n, side) if e > 0]
    edges = [0]
    for e in inner:
        if e - edges[-1] >= side // 4 and n - e >= side // 4:
            edges.append(e)
    return edges + [n]


def data_tile_m(src, cell: float, side: int) -> float | None:
    """The side (m) of a VPC's square tiles when a grid tile can hold one (else None)."""
    if src.vpc is None or len(src.vpc.tiles) < 2:
        return None
    widths = [t.hi[0] - t.lo[0] for t in src.vpc.tiles]
    size = float(np.median(widths))
    return size if 0 < size / cell <= side else None


def tile_side(options: Options, grid: GridSpec, points_per_cell: float, task_gb: float, workers: int) -> int:
    """Tile side (cells): ``options.tile_cells``, else what a task's memory share holds, and
    small enough for two tiles per worker."""
    if options.tile_cells > 0:
        return int(options.tile_cells)
    points = min(4e6, task_gb * 2**30 * 0.5 / TILE_BYTES_PER_POINT)
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


def run_tiles(c, plan: Plan, windows: list[Window], hooks: Hooks, cache: Path | None = None,
              stats: dict | None = None) -> tuple[np.ndarray, ...]:
    """Run every tile on the client ``c`` and assemble (h_a, n_a, s_a, h_b, n_b, s_b) on the grid. Tiles
    found in ``cache`` (from an interrupted run of the same plan) are not run again; finished
    tiles are saved there. ``stats`` sums the tasks' points read and seconds."""
    stats = stats if stats is not None else {}
    stats.update(read=0, seconds=0.0)
    from dask.distributed import as_completed

    g = plan.grid
    out = tuple(np.full((g.rows, g.cols), np.nan) if k % 3 != 1 else np.zeros((g.rows, g.cols), np.int64)
                for k in range(6))
    todo = []
    for win in windows:
        saved = _load_tile(cache, win)
        if saved is None:
            todo.append(win)
        else:
            _place(out, win, saved)
    if len(todo) < len(windows):
        hooks.info(f"resuming: {len(windows) - len(todo)} of {len(windows)} tiles done in an earlier run")
    futures = c.map(grid_tile, [plan] * len(todo), todo, pure=False)
    for k, fut in enumerate(as_completed(futures), 1):
        win, arrays, task = fut.result()
        fut.release()
        for key in stats:
            stats[key] += task[key]
        _place(out, win, arrays)
        _save_tile(cache, win, arrays)
        hooks.step(55 + 15 * k / max(1, len(todo)), f"gridded tile {k}/{len(todo)}")
    return out


def _place(out: tuple[np.ndarray, ...], win: Window, arrays) -> None:
    r0, r1, c0, c1 = win
    for full, part in zip(out, arrays, strict=True):
        full[r0:r1, c0:c1] = part


def _tile_file(cache: Path, win: Window) -> Path:
    return cache / "tile_{}_{}_{}_{}.npz".format(*win)


def _load_tile(cache: Path | None, win: Window):
    if cache is None or not _tile_file(cache, win).exists():
        return None
    try:
        with np.load(_tile_file(cache, win)) as z:
            return tuple(z[k] for k in TILE_ARRAYS)
    except (OSError, ValueError, KeyError):  # a tile cut short by the interruption: run it again
        return None


def _save_tile(cache: Path | None, win: Window, arrays) -> None:
    if cache is None:
        return
    tmp = cache / f".{_tile_file(cache, win).name}"
    with open(tmp, "wb") as f:
        np.savez(f, **dict(zip(TILE_ARRAYS, arrays, strict=True)))
    tmp.replace(_tile_file(cache, win))


def tile_cache(out: OutputDir, plan: Plan) -> Path:
    """The folder keeping finished tiles of ``plan`` until the run succeeds (keyed by the plan,
    so a changed input, option or registration starts afresh)."""
    import hashlib
    import pickle

    key = hashlib.sha1(pickle.dumps((plan.before, plan.after, plan.crs_b, plan.crs_a, plan.origin.tolist(),
                                     plan.grid, plan.transform.round(12).tolist(), plan.ground, plan.statistic)))
    folder = out.final / ".soilvolume-tiles" / key.hexdigest()[:16]
    folder.mkdir(parents=True, exist_ok=True)
    return folder


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
        raise SoilVolumeError(f"--scheduler {options.scheduler}: preparation pipelines run in-process only "
                              "(use --scheduler none)")
    return chosen


def _header_points(path) -> int | None:
    """A LAS/LAZ/COPC file's or a VPC's point count from its header(s); None for other formats."""
    from pathlib import Path

    from .io import LAS_SUFFIXES

    suffix = Path(path).suffix.lower()
    if suffix not in LAS_SUFFIXES | {".vpc"}:
        return None
    return open_source(path).count


def estimate_tiled(before, after, out: OutputDir, options: Options, timer, hooks: Hooks,
                   schedule: Schedule) -> Result:
    """:func:`run._estimate` with the point work as Dask tasks on ``schedule``."""
    if options.ground == "filter":
        raise SoilVolumeError("--ground filter needs whole clouds: use --scheduler none (or classify the tiles first)")
    hooks.step(2, f"reading {before.name} and {after.name} (thinning for registration)")
    with client(schedule, options.memory_limit) as starting:  # workers start while the inputs are opened
        return _tiled(before, after, out, options, timer, hooks, schedule, starting)


def _tiled(before, after, out: OutputDir, options: Options, timer, hooks: Hooks, schedule: Schedule,
           starting) -> Result:
    """The tiled run, with ``starting`` the future of the (cluster, client) being started."""
    from . import run

    with timer("cluster_wait"):
        _, c = starting.result()
    with timer("crop"):  # the registration subsets: a first pass as Dask tasks
        src_b, src_a = open_source(before), open_source(after)
        prep = prepare(src_b, src_a, options, check=lambda: hooks.step(5, "reading"), full=False,
                       loader=dask_loader(c, lambda m: hooks.step(8, m)))
    from .georef import resolve

    mode, why = resolve(options.georeferencing, prep.inputs, prep.after_thin, prep.before_thin)
    hooks.info(f"georeferencing: {mode} ({why})")
    if mode == "precise":
        options = options.with_(correction="none")
    hooks.step(15, "registering (coarse, then fine)")
    with timer("register"):
        reg = register(prep.after_thin, prep.before_thin, options, check=lambda: hooks.step(15, "registering"),
                       precise=mode == "precise")
    reg.georeferencing = {"requested": options.georeferencing, "used": mode, "reason": why}
    timer.s["coarse"], timer.s["fine"] = reg.coarse.seconds, reg.fine.seconds
    timer.s["register_other"] = max(0.0, timer.s.pop("register") - reg.coarse.seconds - reg.fine.seconds)
    after_thin = transform_points(prep.after_thin, reg.transform)
    cell = options.cell if options.cell else cell_from_columns(prep, after_thin)
    grid = run.shared_grid(prep, after_thin, options.with_(cell=cell))
    plan = Plan(str(before), str(after), prep.inputs["before"]["crs_wkt"], prep.inputs["after"]["crs_wkt"],
                prep.frame, prep.origin, grid, reg.transform, prep.ground,
                footprint(prep.after_thin[:, :2], options.radius), options.statistic, prep.index)
    side = tile_side(options, grid, points_per_cell(prep, cell), worker_gb(schedule, options.memory_limit),
                     schedule.workers)
    align = None if options.tile_cells else data_tile_m(src_b, cell, 2 * side)
    if align:  # snap to the input's tiles: rounded tile widths in metres to whole cells
        side = max(1, round(align / cell))
    windows = tiles(grid, side, align)
    hooks.step(55, f"gridding {len(windows)} tiles of {side} x {side} cells on {schedule}")
    cache = tile_cache(out, plan)
    with timer("grids"):
        h_a, n_a, s_a, h_b, n_b, s_b = run_tiles(c, plan, windows, hooks, cache, stats := {})
    with timer("planes"):
        sel_b = run._points_on(prep.before_thin, grid, np.isfinite(h_b))
        p_b = planes.ransac_plane(sel_b, options.plane_threshold, seed=options.seed)
        p_a = planes.ransac_plane(after_thin, options.plane_threshold, seed=options.seed + 1)
        d_i = planes.plane_offset(p_b, p_a, grid)
    hooks.step(75, "computing the difference and volumes")
    with timer("volume"):
        vols = run._volumes(h_a, h_b, n_a, n_b, d_i, grid, options, spread=(s_a, s_b))
        vols["dem_after"] = h_a + prep.origin[2]
    hooks.step(85, "writing outputs (COG)")
    with timer("write"):
        write_outputs(out, h_b, h_a, vols, grid, prep.origin, options)
    with timer("report"):
        report = run._report(prep, reg, grid, vols, p_b, p_a, options, timer)
        report["engine"] = {"scheduler": str(schedule), "tiles": len(windows), "tile_cells": side,
                            "task_points_read": stats["read"], "task_seconds": round(stats["seconds"], 3),
                            "points_per_task_second": round(stats["read"] / max(stats["seconds"], 1e-9))}
        _quality(report, vols, grid, options, hooks)
        write_json(out.path("report.json"), report)
        run._html(out, report, vols, grid)
    shutil.rmtree(cache.parent, ignore_errors=True)
    return Result(report)


def _quality(report: dict, vols: dict, grid: GridSpec, options: Options, hooks: Hooks) -> None:
    """The quality verdict of the in-process run, on the same numbers."""
    from .quality import assess

    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    report["quality"] = assess(report, vols["stable"], vols["change_mask"], vols["offset"], grid.cell_area, prior)
    for line in report["quality"]["messages"]:
        hooks.info(f"quality ({report['quality']['verdict']}): {line}")


def write_outputs(out: OutputDir, h_b, h_a, vols: dict, grid: GridSpec, origin, options: Options) -> None:
    """The five rasters of a run, as COGs written block by block."""
    z0 = float(origin[2])
    layers = [
        ("dem_before.tif", lambda r, c: h_b[r, c] + z0, "average height, before (m)", "float32"),
        ("dem_after.tif", lambda r, c: h_a[r, c] + z0, "average height, after (m)", "float32"),
        ("difference.tif", lambda r, c: vols["diff"][r, c],
         f"H_after - H_before - correction ({options.correction}) (m)", "float32"),
        ("plane_offset.tif", lambda r, c: vols["offset"][r, c],
         f"vertical correction d_i subtracted ({options.correction}) (m)", "float32"),
        ("filled_mask.tif", lambda r, c: vols["filled_mask"][r, c].astype("uint8"),
         "1 = difference interpolated (sparse cell or filled hole)", "uint8"),
    ]
    for name, piece, desc, dtype in layers:
        write_cog(out.path(name), grid, piece, desc, "" if dtype == "uint8" else "metre", dtype)
