"""``soilvolume estimate``: the whole pipeline of :mod:`.run` over two epochs, its outputs
staged and swapped in when all succeeded."""

from __future__ import annotations

from pathlib import Path

from ..core.hooks import Hooks, Result
from ..core.outputs import RUN_OUTPUTS, os_errors, output_dir
from ..core.types import Epoch
from ..inputs.distinct import check_two_surveys
from ..inputs.surface import is_surface
from ..options import Options
from ..pipelines.confine import writers_into
from .run import Run, drive
from .timing import Timer


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
    timer = Timer()  # first: the timings count from here (and the start-up before)
    if before_pipeline is None and after_pipeline is None:  # pipelines may make two clouds of one file
        check_two_surveys(before, after)
    kind = "surface" if is_surface(before) and before_pipeline is None else "survey"  # a design, an earlier DEM
    epochs = (Epoch(before, before_pipeline, kind=kind), Epoch(after, after_pipeline))
    inputs = [before, after, before_pipeline, after_pipeline, options.zones, options.stable_mask]
    with (
        output_dir(out_dir, inputs, overwrite) as out,
        os_errors(out.final),
        writers_into(out.stage, inputs, RUN_OUTPUTS),
    ):
        with timer("setup"):  # the output folder checked, the schedule chosen from the headers
            run = Run("estimate", epochs, options, hooks, timer, out=out)
            if options.keep_registered_cloud:
                run.cloud_out = out.path("after_registered.laz")
            executor = executor_for(run)
        drive(run, executor)
        result = Result(run.report, keyed=run.keyed)
    result.outputs = {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in out.moved.items()}
    hooks.step(100, "done")
    return result


def executor_for(run: Run):
    """The executor the schedule (``--scheduler``, :func:`distributed.schedule.schedule_for`) picks."""
    from ..distributed.schedule import schedule_for
    from .executors import InProcess

    b, a = run.epochs
    if b.kind == "surface":  # the survey alone, in-process (workflow/design)
        from .design import SurfaceReference

        if run.options.scheduler not in ("none", "auto"):
            run.hooks.info("{opt:scheduler}: a run against a surface runs in this process")
        return SurfaceReference()
    schedule = schedule_for(b.path, a.path, run.options, b.pipeline or a.pipeline)
    if schedule.kind == "none":
        return InProcess()
    from ..distributed.executor import Tiled

    return Tiled(schedule)
