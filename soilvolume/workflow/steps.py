"""Steps shared by the in-process run (:mod:`.estimate`) and the tiled one
(:mod:`soilvolume.distributed.tiled`): stage timings, reading the pair, the shared grid, the
points on valid cells, report.html."""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..core.types import GridSpec, SoilVolumeError
from ..dem import grid as gridmod
from ..inputs.footprint import footprint
from ..inputs.prepare import Prepared, prepare
from ..options import Options
from ..validate import check_grid_cells
from ..volumes.compute import Volumes

REGISTERING = "registering the after cloud onto the before cloud (coarse, then fine)"


class Timer:
    """Per-stage wall times (seconds), in the order they ran."""

    def __init__(self) -> None:
        self.s: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.s[name] = self.s.get(name, 0.0) + time.perf_counter() - t0


def shared_grid(prep: Prepared, after_thin: np.ndarray, options: Options) -> GridSpec:
    """The grid over the registered after footprint, cell size from the before density."""
    poly = footprint(after_thin[:, :2])
    cell = options.cell
    if cell is None or cell <= 0:
        cell = gridmod.cell_for(prep.before.xyz, poly)
    lo = np.maximum(after_thin.min(axis=0), prep.before_thin.min(axis=0))
    hi = np.minimum(after_thin.max(axis=0), prep.before_thin.max(axis=0))
    if (hi[:2] <= lo[:2]).any():
        raise SoilVolumeError("the registered after cloud does not overlap the before cloud")
    grid = gridmod.make_grid(lo, hi, cell, prep.origin, prep.frame.wkt, prep.frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    return grid


def prepare_pair(before, after, options: Options, hooks: Hooks, before_pipeline, after_pipeline) -> Prepared:
    from ..inputs.stream import open_source

    src_b, src_a = open_source(before, before_pipeline), open_source(after, after_pipeline)
    return prepare(src_b, src_a, options, check=hooks.ticker(2, 15, "reading"))


def moved_nonsoil(prep: Prepared, reg):
    """The after epoch's points that are not soil, moved by the registration (None without)."""
    ns = prep.after.nonsoil
    return None if ns is None else ns.moved(reg.transform)


def points_on(xyz: np.ndarray, grid: GridSpec, cells: np.ndarray) -> np.ndarray:
    row, col, ok = grid.index(xyz[:, :2])
    keep = np.zeros(len(xyz), bool)
    keep[ok] = cells[row[ok], col[ok]]
    return xyz[keep]


def write_report_html(out: OutputDir, report: dict, vols: Volumes, grid: GridSpec, dem_after: np.ndarray) -> None:
    try:
        from ..reporting.html import write_html
    except ImportError:
        return
    arrays = {
        "difference": vols.diff,
        "residual": np.where(vols.stable, vols.diff, np.nan),
        "filled_mask": vols.filled_mask,
        "classes": vols.classes,
        "dem_after": dem_after,
    }
    write_html(report, arrays, grid, out.path("report.html"))


def planes_and_volumes(
    prep: Prepared,
    reg,
    grid: GridSpec,
    dem_after: gridmod.EpochDEM,
    dem_before: gridmod.EpochDEM,
    after_thin: np.ndarray,
    options: Options,
    timer,
    hooks: Hooks,
):
    """The paper's two RANSAC planes and d_i, then the volume step, from both epochs' DEMs:
    (Volumes, plane before, plane after)."""
    from ..compensation import planes
    from ..volumes.compute import compute_volumes

    with timer("planes"):
        sel_b = points_on(prep.before_thin, grid, np.isfinite(dem_before.heights))
        p_b = planes.ransac_plane(sel_b, options.plane_threshold, seed=options.seed)
        p_a = planes.ransac_plane(after_thin, options.plane_threshold, seed=options.seed + 1)
        d_i = planes.plane_offset(p_b, p_a, grid)
    hooks.step(75, "computing the difference and volumes")
    with timer("volume"):
        vols = compute_volumes(dem_after, dem_before, d_i, grid, options, moved=alternative_move(reg))
    return vols, p_b, p_a


def correction_step(options: Options) -> str:
    """The progress message of the correction step: what it does with these options."""
    if options.correction == "none":
        return "comparing the surfaces (no vertical bias correction)"
    return "estimating the vertical bias correction"


def alternative_move(reg) -> np.ndarray | None:
    """The rigid move (4x4, local) from the accepted pose to the nearly as good one (None)."""
    alt = reg.fine.alternative
    return None if alt is None else alt @ np.linalg.inv(reg.transform)


def add_quality(report: dict, vols: Volumes, grid: GridSpec, options: Options, hooks: Hooks) -> None:
    """The quality verdict (see :mod:`soilvolume.volumes.quality`) into ``report``, logged."""
    from ..volumes.quality import assess

    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    report["quality"] = assess(report, vols.stable, vols.change_mask, vols.offset, grid.cell_area, prior, vols.diff)
    for line in report["quality"]["messages"]:
        hooks.info(f"quality ({report['quality']['verdict']}): {line}")


def register_pair(prep: Prepared, options: Options, hooks: Hooks, timer, dense=None):
    """Decide how far the georeferencing is trusted, then register: (Registration, the options
    the rest of the run uses; precise surveys get no bias correction)."""
    from ..registration.georef import resolve
    from ..registration.register import register

    mode, why = resolve(options.georeferencing, prep.inputs, prep.after_thin, prep.before_thin)
    hooks.info(f"georeferencing: {mode} ({why})")
    if mode == "precise":
        options = options.with_(correction="none")
    hooks.step(15, REGISTERING)
    with timer("register"):
        reg = register(
            prep.after_thin,
            prep.before_thin,
            options,
            check=hooks.ticker(15, 55, REGISTERING),
            dense=dense,
            precise=mode == "precise",
        )
    reg = replace(reg, georeferencing={"requested": options.georeferencing, "used": mode, "reason": why})
    timer.s["coarse"], timer.s["fine"] = reg.coarse.seconds, reg.fine.seconds
    timer.s["register_other"] = max(0.0, timer.s.pop("register") - reg.coarse.seconds - reg.fine.seconds)
    return reg, options
