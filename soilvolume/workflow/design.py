"""``soilvolume estimate DESIGN.tif AFTER.laz``: a survey against a surface (a grading plan or an earlier DEM,
:mod:`soilvolume.inputs.surface`), in memory: nothing registered, the surface resampled onto the survey's grid
as the before DEM, the volume step as for a pair (no bias correction unless asked) with the surface's error
terms; the survey's agreement with the surface on unchanged ground leads the verdict (volumes/reference)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.cells import bounds
from ..core.hooks import Hooks
from ..core.record import Georeferencing, RunRecord
from ..core.types import GridSpec, SoilVolumeError, StageQuality
from ..dem.geotiff import write_grid
from ..dem.grid import EpochDEM, epoch_dem, output_layers
from ..execution.seam import Backend, Gridded, done
from ..inputs.heights import masked_notes
from ..inputs.landxml import Tin
from ..inputs.prepare import Prepared, prepare_survey
from ..inputs.surface import Surface, on_grid, open_surface, read_over, valid_box
from ..options import Options
from ..pipelines.pipeline import open_source
from ..registration.register import Registration
from ..reporting.surface import NONE
from ..volumes import reference
from ..volumes.compute import Volumes, compute_volumes
from ..volumes.grade import grade
from . import steps
from .context import Context
from .plan import plan_grid, survey_cell

NOT_REGISTERED = (
    f"registration: {NONE} (nothing is registered against a design: the survey must be well georeferenced; "
    "its agreement with the design on unchanged ground is checked)"
)
DESIGN_COUNT = 1000  # the points a surface cell stands for: never weak, never refilled as sparse
STEPS = ("prepare", "grid", "volume", "write", "report")  # nothing registered, no planes
#: the estimate's rasters said otherwise against a surface (dem_before.tif is the surface on the grid)
SAID = {
    "dem_out_b": "the reference surface (design) resampled onto the grid, bilinear at the cell centres (m)",
    "diff": "survey - design (m): above design > 0 (fill), below design < 0 (cut)",
}


class NoPlane:
    """The paper's planes do not apply to a surface: report.json's ``planes`` are null."""

    def as_dict(self, origin) -> None:
        return None


def estimate(ctx: Context, backend: Backend) -> tuple[dict, dict]:
    """Read the surface and the survey, grid, volume (with the surface's terms), write, report."""
    if ctx.schedule is not None and not ctx.schedule.in_process:  # None: auto
        ctx.hooks.info("{opt:scheduler}: a run against a surface runs in this process")
    with backend.session(ctx):
        ctx, prep, surface, cell = read(ctx)
        gridded, sigma = grid(ctx, prep, surface, cell)
        fitted = (NoPlane(), NoPlane(), np.zeros((gridded.grid.rows, gridded.grid.cols)))

        def step(after: EpochDEM, before: EpochDEM, d_i: np.ndarray, on: GridSpec) -> Volumes:
            return reference.with_surface(compute_volumes(after, before, d_i, on, ctx.options), sigma, ctx.options, on)

        with steps.running(ctx, "volume", ctx.message("volume")):
            vols = backend.volume(ctx, step, gridded, fitted, None)
        layers = [(name, key, SAID.get(key, desc)) for name, key, desc in output_layers("none")]
        extras = steps.write(ctx, backend, vols, gridded.grid, layers)
        if ctx.options.tolerance is not None:  # grade.tif (uint8: 1 cut to go, 2 on grade, 3 fill to go, 255
            # not compared) and report.json's ``grade`` (:func:`volumes.grade.grade`)
            cls, extras["grade"] = grade(vols.diff, gridded.grid, ctx.options.tolerance, ctx.options.zones)
            said = f"1 cut to go, 2 on grade (within {ctx.options.tolerance:g} m of the design), 3 fill to go"
            write_grid(ctx.out.path("grade.tif"), cls, gridded.grid, said, units="", dtype="uint8")
        judged = steps.judged(vols, gridded.grid, ctx.options)
        stage = StageQuality(NONE, float("nan"), float("nan"), accepted=False, note=NONE)  # nothing registered
        geo = Georeferencing(ctx.options.georeferencing, "none", "the reference is a surface")
        reg = Registration(np.eye(4), stage, stage, geo)
        record = RunRecord(prep, reg, gridded.grid, fitted[:2], vols, ctx.options, judged, backend.engine())
        return steps.report(ctx, record, gridded, extras)


def read(ctx: Context) -> tuple[Context, Prepared, Surface | Tin, float]:
    """The surface opened and checked (before any point), the survey, the cell, the surface's heights over
    the survey's box and two cells around it (the grid's edges, the resampling's kernel: a design far larger
    than the site costs only the site's window): (the run with its options for a surface, the survey, the
    surface, the cell)."""
    design, after = ctx.epochs
    with steps.running(ctx, "prepare", ctx.message("prepare") + " (the reference is a surface)", "crop"):
        source = open_surface(Path(design.path), ctx.options.before_crs, ctx.options.design_surface)
        ctx = replace(ctx, options=_options(ctx.options, ctx.hooks))
        check = ctx.hooks.ticker(*ctx.spans["prepare"], "reading")
        prep = prepare_survey(open_source(after.path, after.pipeline), ctx.options, check=check)
        ctx.timer.s["read"] = prep.read_s
        ctx.timer.s["crop"] = ctx.timer.s.get("crop", 0.0) - prep.read_s
        cell = survey_cell(prep.after.xyz, prep.after_thin, ctx.options)
        (lo, hi), origin = bounds(prep.after_thin, 2), prep.origin[:2]  # the native one pass
        surface = read_over(source, lo + origin, hi + origin, prep.frame, 2 * cell)
        for note in masked_notes(source.path, surface.masked):
            ctx.hooks.info(note)
        ctx.hooks.info(NOT_REGISTERED)
    return ctx, replace(prep, inputs={"before": surface.describe(), **prep.inputs}), surface, cell


def grid(ctx: Context, prep: Prepared, surface: Surface | Tin, cell: float) -> tuple[Gridded, np.ndarray]:
    """The survey's grid of ``cell`` over its footprint clipped to the surface's valid extent, its DEM and the
    surface's on it: (the DEMs, the surface's per-cell error)."""
    with steps.running(ctx, "grid", ctx.message("grid"), "grids"):
        box_lo, box_hi = valid_box(surface, prep.frame.crs, prep.frame.xy_unit)
        thin, origin = prep.after_thin[:, :2], prep.origin[:2]
        missed = f"{surface.path} does not overlap {prep.after.path}"
        empty = f"{missed}: the surface's valid extent misses the survey (check the CRSs)"
        on = plan_grid(cell, [thin, (box_lo - origin, box_hi - origin)], prep.origin, prep.frame, empty)
        dem_a = epoch_dem(prep.after.xyz, on, ctx.options.statistic, prep.after.nonsoil)
        dem_s, sigma = surface_epoch(surface, on, ctx.options.design_uncertainty)
        if not (np.isfinite(dem_a.heights) & np.isfinite(dem_s.heights)).any():
            raise SoilVolumeError(f"{missed}: no cell of the survey has a surface height")
    return Gridded(on, (dem_a, dem_s), on, (dem_a, dem_s), done(None)), sigma


def _options(options: Options, hooks: Hooks) -> Options:
    """No bias correction against a design unless one is asked for (the default is refitted to
    none: a design is not the existing ground); the paper's planes need two clouds."""
    if options.correction == "paper-plane":
        raise SoilVolumeError(
            "{opt:correction=paper-plane} needs two point clouds; against a surface: none (the default), plane, surface"
        )
    if options.keep_registered_cloud:
        hooks.info("--registered-cloud: nothing is registered against a surface, so no registered cloud is written")
    if options.correction == Options().correction:
        hooks.info("bias correction: none (the design is not the existing ground; {opt:correction=plane} fits one)")
        return options.with_(correction="none", keep_registered_cloud=False)
    hooks.info(f"bias correction against the surface: {options.correction} on the unchanged ground, as asked")
    return options.with_(keep_registered_cloud=False)


def surface_epoch(surface: Surface | Tin, grid: GridSpec, given_m: float) -> tuple[EpochDEM, np.ndarray]:
    """(the surface bilinear at ``grid``'s centres as the before epoch, each cell's one-sigma error: its difference
    from cubic with ``given_m`` in quadrature, the standard error of :data:`DESIGN_COUNT` points so the LoD has it)."""
    z = on_grid(surface, grid) - grid.origin[2]
    cubic = z if isinstance(surface, Tin) else on_grid(surface, grid, "cubic") - grid.origin[2]  # a TIN is exact
    valid = np.isfinite(z)
    sigma = np.where(valid, np.hypot(np.nan_to_num(np.abs(z - cubic)), given_m), np.nan)
    counts = np.where(valid, DESIGN_COUNT, 0).astype(np.int64)
    return EpochDEM(z, counts, sigma * np.sqrt(DESIGN_COUNT)), sigma
