"""The method's steps, each written once: read, register, grid, planes, volume, write, report.

Each takes the run's :class:`~.context.Context`, the backend doing its point work and the earlier
steps' results, reports its progress, times itself and returns a frozen typed result; the products
(:mod:`.pair`, :mod:`.design`, :mod:`.series`, ...) are compositions of them."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from functools import partial

import numpy as np

from ..compensation.planes import Plane, plane_offset, ransac_plane
from ..core.record import Georeferencing, QualityInputs, RunRecord
from ..core.types import GridSpec
from ..core.wording import cli_tree, opt
from ..dem.grid import EpochDEM
from ..execution.seam import Backend, Gridded
from ..inputs.footprint import footprint
from ..inputs.prepare import Prepared, Single, prepare_single
from ..options import Options
from ..pipelines.pipeline import open_source
from ..registration import georef
from ..registration.register import Registration
from ..registration.register import register as register_clouds
from ..registration.rigid import transform_points
from ..reporting.contours import FILE as CONTOURS
from ..reporting.contours import write_contours
from ..reporting.html import write_html
from ..reporting.report import build_report, write_json
from ..reporting.sections import write_sections
from ..reporting.vectors import FILE as CHANGE_AREAS
from ..reporting.vectors import write_change_areas, write_zones
from ..volumes.compute import Volumes, compute_volumes
from .context import Context
from .plan import plan_grid, reference_cell


@contextmanager
def running(ctx: Context, step: str, message: str, timed: str | None = None, log: bool = True) -> Iterator[None]:
    """A step's progress line and its time in ``timed`` (the step's name)."""
    ctx.hooks.step(ctx.at(step), message, log=log)
    with ctx.timer(timed or step):
        yield


def read(ctx: Context, backend: Backend) -> Prepared:
    """Step 1: the pair read into one working frame (:mod:`soilvolume.inputs.prepare`)."""
    with running(ctx, "prepare", ctx.message("prepare") + backend.reading_note, "crop"):
        return backend.read(ctx)


def read_one(ctx: Context) -> Single:
    """Step 1 of one survey (``dem``, ``stockpile``): streamed into its own frame, its ground and soil points."""
    (epoch,) = ctx.epochs
    check = ctx.hooks.ticker(*ctx.spans["prepare"], "reading")
    return prepare_single(open_source(epoch.path, epoch.pipeline), epoch.crs, ctx.options, check=check)


def register(ctx: Context, prep: Prepared, dense, progress: tuple | None = None) -> tuple[Registration, Options]:
    """Step 2: how far the georeferencing is trusted, then coarse + fine registration (``dense``: the full-resolution
    points of the stable-ground refinement, or None): (Registration, the options the rest of the run uses: precise
    georeferencing, no correction). Auto with a vertical datum both files declare keeps the coordinates only when
    the registration confirms them (:func:`registration.georef.confirm`); ``register_other`` times the decision.
    ``progress``: (start %, end %, message) of a series' pair (it logs its own fit), else the step's."""
    options, hooks, timer = ctx.options, ctx.hooks, ctx.timer
    with timer("register"):
        lo, hi, message = progress or (*ctx.spans["register"], ctx.message("register"))
        hooks.step(lo, message)
        after, before = prep.after_thin, prep.before_thin
        decided, check = georef.declared(options.georeferencing, prep.inputs), None
        mode, why = decided or ("gps", "")
        ticker = hooks.ticker(lo, hi, message)
        reg = ran = register_clouds(after, before, options, check=ticker, dense=dense, precise=mode == "precise")
        if decided is None:
            datum = georef.vertical_datum(prep.inputs["after"].get("crs_wkt"))
            mode, why, check = georef.confirm(reg, after, before, datum, options.fine)
            if mode == "precise":  # the identity registration of coordinates auto kept, its stages saying why
                kept = register_clouds(after, before, options, precise=True)
                said = "confirmed them" if check["outcome"] == "confirmed" else "could not confirm them"
                note = "not applied: coordinates used as georeferenced (the registration "
                note += f"{said}; see {opt('georeferencing')})"
                reg = replace(kept, coarse=replace(kept.coarse, note=note), fine=replace(kept.fine, note=note))
        hooks.info(f"georeferencing: {mode} ({why})")
        if mode == "precise":
            options = options.with_(correction="none")
    reg = replace(reg, georeferencing=Georeferencing(options.georeferencing, mode, why, check))
    timer.s["coarse"], timer.s["fine"] = ran.coarse.seconds, ran.fine.seconds
    timer.s["register_other"] = max(0.0, timer.s.pop("register") - ran.coarse.seconds - ran.fine.seconds)
    if progress is None:
        hooks.info(f"coarse: {reg.coarse.note}")
        hooks.info(
            f"fine ({reg.fine.method}): fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m, {reg.fine.note}"
        )
    return reg, options


def grid(ctx: Context, backend: Backend, prep: Prepared, reg: Registration) -> Gridded:
    """Step 3: the grid planned over the registered after footprint and the before subset (:mod:`.plan`),
    each epoch's heights on it, the paper's planes fitted beside."""
    with running(ctx, "grid", ctx.message("grid"), "grids"):
        after_thin = transform_points(prep.after_thin, reg.transform)
        poly = footprint(after_thin[:, :2])
        empty = "the registered after cloud does not overlap the before cloud"
        cell = reference_cell(prep, poly, ctx.options)
        plan = plan_grid(cell, [after_thin, prep.before_thin], prep.origin, prep.frame, empty)
        return backend.grid(ctx, prep, reg, plan, fit_planes(prep, after_thin, ctx.options))


def fit_planes(prep: Prepared, after_thin: np.ndarray, options: Options) -> Callable:
    """The paper's two RANSAC planes on a grid and its before DEM: the before's thinned points over
    the cells it has heights in, and the registered after's."""

    def fit(grid: GridSpec, dem_before: EpochDEM) -> tuple[Plane, Plane]:
        row, col, ok = grid.index(prep.before_thin[:, :2])
        valid = np.zeros(len(prep.before_thin), bool)
        valid[ok] = np.isfinite(dem_before.heights)[row[ok], col[ok]]
        before = ransac_plane(prep.before_thin[valid], options.plane_threshold, seed=options.seed)
        return before, ransac_plane(after_thin, options.plane_threshold, seed=options.seed + 1)

    return fit


def planes(ctx: Context, gridded: Gridded) -> tuple:
    """Step 4: (plane before, plane after, d_i) on the grid the correction is found on."""
    k = round(gridded.correction_grid.cell / gridded.grid.cell)
    overview = f"estimating the vertical bias correction on a {k} x {k} overview of the grid"
    with running(ctx, "planes", overview if k > 1 else correction_message(ctx.options)):
        p_b, p_a = gridded.beside.result()
        return p_b, p_a, plane_offset(p_b, p_a, gridded.correction_grid)


def correction_message(options: Options) -> str:
    """The progress message of the correction step: what it does with these options."""
    if options.correction == "none":
        return "comparing the surfaces (no vertical bias correction)"
    return "estimating the vertical bias correction"


def volume(ctx: Context, backend: Backend, gridded: Gridded, fitted: tuple, reg: Registration) -> Volumes:
    """Step 5: difference, refill, correction, change areas, budgets, uncertainty, zones."""
    with running(ctx, "volume", ctx.message("volume")):
        return backend.volume(ctx, volume_step(reg, ctx.options), gridded, fitted, alternative_move(reg))


def volume_step(reg: Registration, options: Options) -> Callable:
    """The volume step of a pair registered by ``reg``, as a backend runs it (``seam.VolumeFn``)."""
    return partial(compute_volumes, options=options, moved=alternative_move(reg))


def alternative_move(reg: Registration) -> np.ndarray | None:
    """The rigid move (4x4, local) from the accepted pose to the nearly as good one (None)."""
    alt = reg.fine.alternative
    return None if alt is None else alt @ np.linalg.inv(reg.transform)


def write(ctx: Context, backend: Backend, vols: Volumes | None, grid: GridSpec | None, layers: list) -> dict:
    """Step 6: the rasters ``layers`` (and the registered cloud, when kept), then from them contours.gpkg
    (``--contour-interval``) and the sections (``--sections``): their report.json entries."""
    extras = {}
    with running(ctx, "write", ctx.message("write") + backend.raster_note):
        z0 = 0.0 if grid is None else float(grid.origin[2])  # local -> absolute heights
        backend.write(ctx, layers, vols, grid, z0)
        staged = ctx.out.path(CONTOURS) if layers else None
        if layers and ctx.options.contour_interval > 0:
            extras["contours"] = write_contours(staged, staged.parent, ctx.options.contour_interval)
        if layers and grid is not None and ctx.options.sections:
            before = "design" if ctx.epochs[0].is_surface else "before"
            extras["sections"] = write_sections(ctx.options.sections, staged.parent, grid, before)
    return extras


def report(ctx: Context, record: RunRecord, gridded: Gridded, extras: dict | None) -> tuple[dict, dict]:
    """Step 7: report.json from the run's record (its verdict, the write step's ``extras``), report.html and
    the areas of significant change as polygons: report.json as written (options worded for the command
    line) and with options by key."""
    with running(ctx, "report", ctx.message("report"), log=False):
        out, vols, z0 = ctx.out, record.vols, float(gridded.grid.origin[2])
        report = build_report(record, ctx.timer.totals())
        report.update(extras or {})
        for line in report["quality"]["messages"]:
            ctx.hooks.info(f"quality ({report['quality']['verdict']}): {line}")
        on = gridded.correction_grid  # a tiled run's overview: the arrays the report shows are its
        gpkg = ctx.options.gpkg
        write_change_areas(out.path(CHANGE_AREAS), vols.diff, vols.change_mask, vols.cut_mask, on, gpkg)
        if ctx.options.zones and report.get("zones"):  # zones.csv (and zones.gpkg)
            write_zones(out.path(CHANGE_AREAS).parent, report["zones"], ctx.options.zones, gridded.grid, gpkg)
        arrays = {
            "difference": vols.diff,
            "residual": np.where(vols.stable, vols.diff, np.nan),
            "filled_mask": vols.filled_mask,
            "classes": vols.classes,
            "dem_after": gridded.correction_dems[0].heights + z0,
            "change": vols.change_mask,
        }
        write_html(report, arrays, on, out.path("report.html"))
        worded = cli_tree(report)  # options worded for the command line
        write_json(out.path("report.json"), worded, ctx.timer.totals())
        return worded, report


def judged(vols: Volumes, grid: GridSpec, options: Options) -> QualityInputs:
    """What the quality verdict judges of a run, on ``grid`` (the correction's)."""
    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    return QualityInputs(vols.stable, vols.change_mask, vols.offset, vols.diff, grid.cell_area, prior)
