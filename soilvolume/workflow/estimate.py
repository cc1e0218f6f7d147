"""``soilvolume estimate``: a pair (:func:`estimate_pair`: the method's steps over two surveys, the first the
reference, on the backend of ``--scheduler``) or a survey against a surface (:mod:`.design`), its outputs staged
and swapped in when all succeeded."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..core.hooks import Hooks, Result
from ..core.outputs import RUN_OUTPUTS, os_errors, output_dir
from ..core.record import RunRecord
from ..core.types import Epoch, SoilVolumeError, survey
from ..dem.grid import output_layers
from ..distributed.schedule import schedule_for
from ..execution.inmemory import InMemory
from ..execution.seam import Backend
from ..execution.tiled import Tiled
from ..inputs.io import check_two_surveys
from ..inputs.surface import is_surface
from ..options import Options
from ..pipelines.confine import writers_into
from ..validate import schedule_of
from . import design, steps
from .context import PAIR, Context, Timer, threads


def run_estimate(
    before: str | Path,
    after: str | Path,
    out_dir: str | Path,
    options: Options | None = None,
    *,
    overwrite: bool = False,
    hooks: Hooks | None = None,
    before_pipeline: str | Path | None = None,
    after_pipeline: str | Path | None = None,
) -> Result:
    """The whole method (``api.estimate``): read, crop, register, compensate, grid, difference, volumes, report."""
    options, hooks, before, after = options or Options(), hooks or Hooks(), Path(before), Path(after)
    timer = Timer()  # first: the timings count from here (and the start-up before)
    schedule = schedule_of(options)  # the one parse of --scheduler, before any file is read
    if before_pipeline is None and after_pipeline is None:  # pipelines may make two clouds of one file
        check_two_surveys(before, after)
    given = {"georeferencing": options.georeferencing}  # the first epoch a surface when it is one (a design, a DEM)
    if before_pipeline is None and is_surface(before):
        first = Epoch(before, "surface", crs=options.before_crs)
    else:
        first = survey(before, before_pipeline, crs=options.before_crs, **given)
    epochs = first, survey(after, after_pipeline, crs=options.after_crs, **given)
    if options.tolerance is not None and not epochs[0].is_surface:
        raise SoilVolumeError(
            "{opt:tolerance}: an on-grade tolerance needs a design as BEFORE (a GeoTIFF or LandXML surface), "
            f"not the point cloud {before}"
        )
    inputs = [before, after, before_pipeline, after_pipeline, options.zones, options.stable_mask, options.sections]
    threads(options)
    with (
        output_dir(Path(out_dir), inputs, overwrite) as out,
        os_errors(out.final),
        writers_into(out.stage, inputs, RUN_OUTPUTS),
    ):
        surface = epochs[0].is_surface
        with timer("setup"):  # the output folder checked, the schedule chosen from the headers
            ctx = Context(epochs, options, hooks, design.STEPS if surface else PAIR, timer, out, schedule=schedule)
            b, a = epochs  # the backend of the run's schedule (auto resolved from the headers): tiles but for none
            plan = None if surface else schedule_for(schedule, b.path, a.path, options, b.pipeline or a.pipeline)
            backend = InMemory() if surface or plan.in_process else Tiled(plan)
        report, keyed = (design.estimate if surface else estimate_pair)(ctx, backend)
    hooks.step(100, "done")
    return Result.written(report, out.moved, keyed)


def estimate_pair(ctx: Context, backend: Backend) -> tuple[dict, dict]:
    """Read, register (the registered after cloud kept with ``--registered-cloud``), grid, planes, volume, write,
    report."""
    with backend.session(ctx):
        prep = steps.read(ctx, backend)
        reg, options = steps.register(ctx, prep, backend.dense(prep))
        if options.keep_registered_cloud:
            backend.keep_cloud(prep, reg, ctx.out.path("after_registered.laz"))
        ctx = replace(ctx, options=options)
        gridded = steps.grid(ctx, backend, prep, reg)
        fitted = steps.planes(ctx, gridded)
        vols = steps.volume(ctx, backend, gridded, fitted, reg)
        extras = steps.write(ctx, backend, vols, gridded.grid, output_layers(ctx.options.correction))
        judged = steps.judged(vols, gridded.correction_grid, ctx.options)
        parts = (prep, reg, gridded.grid, fitted[:2], vols, ctx.options, judged, backend.engine())
        return steps.report(ctx, RunRecord(*parts), gridded, extras)
