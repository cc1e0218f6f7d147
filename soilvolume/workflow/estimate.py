"""Orchestration of the method, step by step, with timings, progress and all-or-nothing outputs."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ..core.hooks import Hooks, Result
from ..core.outputs import RUN_OUTPUTS, OutputDir, os_errors, output_dir
from ..core.types import GridSpec
from ..dem import grid as gridmod
from ..inputs.io import write_las_chunked
from ..inputs.prepare import Prepared
from ..options import Options
from ..pipelines.confine import writers_into
from ..registration.rigid import transform_points, transform_points32
from ..reporting.report import build_report, write_json
from ..volumes.compute import Volumes
from .steps import (
    Timer,
    add_quality,
    correction_step,
    moved_nonsoil,
    planes_and_volumes,
    prepare_pair,
    register_pair,
    shared_grid,
    write_report_html,
)


def _threads(options: Options) -> None:
    if options.threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(options.threads))


def run_estimate(
    before: Path,
    after: Path,
    out_dir: Path,
    options: Options,
    *,
    overwrite: bool,
    hooks: Hooks,
    before_pipeline=None,
    after_pipeline=None,
) -> Result:
    """See :func:`soilvolume.api.estimate`."""
    _threads(options)
    timer = Timer()
    inputs = [before, after, before_pipeline, after_pipeline, options.zones, options.stable_mask]
    with (
        output_dir(out_dir, inputs, overwrite) as out,
        os_errors(out.final),
        writers_into(out.stage, inputs, RUN_OUTPUTS),
    ):
        result = _estimate(before, after, out, options, timer, hooks, before_pipeline, after_pipeline)
    result.outputs = {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in out.moved.items()}
    hooks.step(100, "done")
    return result


def _estimate(
    before, after, out: OutputDir, options: Options, timer: Timer, hooks: Hooks, before_pipeline, after_pipeline
) -> Result:
    from ..distributed.tiled import schedule_for
    from ..inputs.surface import is_surface

    if is_surface(before) and before_pipeline is None:  # a design or an earlier DEM as the reference
        from .design import estimate_surface

        return estimate_surface(before, after, out, options, timer, hooks, after_pipeline)
    schedule = schedule_for(before, after, options, before_pipeline or after_pipeline)
    if schedule.kind != "none":
        from ..distributed.tiled import estimate_tiled

        return estimate_tiled(before, after, out, options, timer, hooks, schedule)
    hooks.step(2, f"reading {before.name} and {after.name} (cropping and thinning on the way)")
    with timer("crop"):
        prep = prepare_pair(before, after, options, hooks, before_pipeline, after_pipeline)
    timer.s["read"] = prep.read_s  # the rest of streaming: frame, crop, thinning
    timer.s["crop"] -= prep.read_s
    hooks.info(
        f"kept {len(prep.before):,} before points within {options.radius:g} m of the after "
        f"footprint and {len(prep.after):,} after points; registration subsets "
        f"{len(prep.before_thin):,} + {len(prep.after_thin):,} ({prep.voxel:.2f} m columns)"
    )
    reg, options = register_pair(prep, options, hooks, timer, dense=(prep.after.xyz, prep.before.xyz))
    hooks.info(f"coarse: {reg.coarse.note}")
    hooks.info(f"fine ({reg.fine.method}): fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m, {reg.fine.note}")
    hooks.step(55, "gridding the average heights")
    with ThreadPoolExecutor(2) as pool:  # numpy sorts and LAZ compression release the GIL
        cloud_job = _write_registered(pool, out, prep, reg, options)
        with timer("grids"):
            after_xyz = transform_points32(prep.after.xyz, reg.transform)
            after_thin = transform_points(prep.after_thin, reg.transform)
            grid = shared_grid(prep, after_thin, options)
            before_job = pool.submit(gridmod.epoch_dem, prep.before.xyz, grid, options.statistic, prep.before.nonsoil)
            dem_a = gridmod.epoch_dem(after_xyz, grid, options.statistic, moved_nonsoil(prep, reg))
            del after_xyz
            dem_b = before_job.result()
        hooks.step(70, correction_step(options))
        vols, p_b, p_a = planes_and_volumes(prep, reg, grid, dem_a, dem_b, after_thin, options, timer, hooks)
        hooks.step(85, "writing outputs")
        with timer("write"):
            _write_rasters(out, vols, grid, prep, options)
            if cloud_job is not None:
                cloud_job.result()
    with timer("report"):
        report = build_report(prep, reg, grid, vols, p_b, p_a, options, timer)
        add_quality(report, vols, grid, options, hooks)
        write_json(out.path("report.json"), report)
        write_report_html(out, report, vols, grid, dem_a.heights + prep.origin[2])
    return Result(report)


def _write_registered(pool: ThreadPoolExecutor, out: OutputDir, prep: Prepared, reg, options: Options):
    """Start writing after_registered.laz (every after point, all classes, moved by the
    registration) in the background (None when not asked for)."""
    if not options.keep_registered_cloud:
        return None
    return pool.submit(
        write_las_chunked,
        out.path("after_registered.laz"),
        prep.after_chunks(),
        prep.origin,
        prep.frame.wkt,
        reg.transform,
    )


def _write_rasters(out: OutputDir, vols: Volumes, grid: GridSpec, prep: Prepared, options: Options) -> None:
    z0 = float(prep.origin[2])  # local -> absolute heights
    for name, key, desc in gridmod.output_layers(options.correction):
        array = getattr(vols, key)
        if key in gridmod.UINT8_LAYERS:
            gridmod.write_geotiff(out.path(name), array.astype("uint8"), grid, desc, "", "uint8")
        else:
            gridmod.write_geotiff(out.path(name), array + z0 if key.startswith("dem_") else array, grid, desc)
