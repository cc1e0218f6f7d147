"""The one orchestrator: a run is the method's steps in order, driven once, each step's point work
done by an executor chosen from the schedule (in-process arrays, :mod:`.executors`, or tile
tasks, :mod:`soilvolume.distributed.executor`). Every command is a shortened run of the same
pipeline (:data:`COMMAND_STEPS`); one progress table (:data:`PROGRESS`) serves them all."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.collector import resume
from ..core.hooks import Hooks
from ..core.types import Epoch, GridSpec
from ..options import Options
from ..reporting.contours import FILE as CONTOURS
from ..reporting.contours import write_contours
from .timing import Timer

#: step -> (start %, end %, message) of an estimate; a shorter run spreads its steps over 0-100
PROGRESS: dict[str, tuple[float, float, str]] = {
    "prepare": (2, 15, "reading {epochs}"),
    "register": (15, 55, "registering the after cloud onto the before cloud (coarse, then fine)"),
    "grid": (55, 70, "gridding the average heights"),
    "planes": (70, 75, "estimating the vertical bias correction"),  # or none: steps.correction_step
    "volume": (75, 85, "computing the difference and volumes"),
    "write": (85, 97, "writing outputs"),
    "report": (97, 100, "writing the report"),
}
#: the steps of each command, in the pipeline's order
COMMAND_STEPS: dict[str, tuple[str, ...]] = {
    "estimate": tuple(PROGRESS),
    "register": ("prepare", "register", "write"),
    "dem": ("prepare", "grid", "write"),
    "series": tuple(PROGRESS),  # E0 and each later epoch: workflow/series.Series
    "surface": ("prepare", "grid", "volume", "write", "report"),  # estimate against a surface: nothing registered
}


def spans(steps: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """Each step's percent range: the table's for a whole run, its share of 0-100 for a shorter one."""
    if steps == tuple(PROGRESS):
        return {s: PROGRESS[s][:2] for s in steps}
    widths = [PROGRESS[s][1] - PROGRESS[s][0] for s in steps]
    total, at, out = sum(widths), 0.0, {}
    for s, w in zip(steps, widths, strict=True):
        out[s] = (round(100 * at / total, 1), round(100 * (at + w) / total, 1))
        at += w
    return out


@dataclass
class Run:
    """A run's inputs and what its steps produced so far (the executors fill it in)."""

    command: str
    epochs: tuple[Epoch, ...]
    options: Options
    hooks: Hooks
    timer: Timer = field(default_factory=Timer)
    out: Any = None  # core.outputs.OutputDir of an estimate
    cloud_out: Path | None = None  # where the registered after cloud goes (register, --registered-cloud)
    raster_out: Path | None = None  # the DEM of a dem run
    crs: str | None = None  # dem: the cloud's CRS when its header has none
    bounds: tuple | None = None  # dem: xmin, ymin, xmax, ymax in the cloud's CRS
    spans: dict = field(default_factory=dict)
    prep: Any = None  # inputs.prepare.Prepared (Single for one epoch)
    reg: Any = None  # registration.register.Registration
    grid: GridSpec | None = None
    after_thin: np.ndarray | None = None  # the registered after subset
    dems: tuple = ()  # (after, before) dem.grid.EpochDEMs, or (the one epoch's centred heights,)
    planes: tuple = ()  # (plane before, plane after, d_i)
    vols: Any = None  # volumes.compute.Volumes
    report: dict | None = None  # report.json of an estimate
    keyed: dict | None = None  # the same with its options by key (wording.opt), for front ends
    contours: dict | None = None  # contours.gpkg of an estimate (--contour-interval)

    def at(self, step: str, fraction: float = 0.0) -> float:
        """The percent ``fraction`` of the way through ``step``."""
        lo, hi = self.spans[step]
        return lo + (hi - lo) * fraction

    def message(self, step: str) -> str:
        """The progress table's message of ``step``, naming the run's epochs."""
        return PROGRESS[step][2].format(epochs=" and ".join(e.name for e in self.epochs))


def threads(command: str, options: Options) -> None:
    """``--threads`` of the commands that take it, for OpenMP libraries (OMP_NUM_THREADS; Open3D 0.19+
    runs on oneTBB and gets it from :func:`soilvolume.registration.o3d.limit_threads`; numpy's BLAS
    runs on one thread in the command's process: :func:`soilvolume.__main__.one_blas_thread`)."""
    from ..options import command_fields

    if any(f.name == "threads" for f in command_fields(command)) and options.threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(options.threads))


def drive(run: Run, executor) -> Run:
    """Run the command's steps in order on ``executor`` (see module); returns ``run`` filled in.
    An executor over more than a pair (:class:`soilvolume.workflow.series.Series`) may do a whole
    step itself (``<step>_step(run)``: register, planes, report over every pair); the order,
    the spans and the messages stay the run's. An estimate against a surface skips register and
    planes (``COMMAND_STEPS["surface"]``, :class:`soilvolume.workflow.design.SurfaceReference`)."""
    surface = run.command == "estimate" and run.epochs[0].kind == "surface"
    steps = COMMAND_STEPS["surface" if surface else run.command]
    run.spans = spans(steps)
    threads(run.command, run.options)
    with executor.session(run):
        for name in steps:
            own = getattr(executor, f"{name}_step", None)  # a series' executor: the step over every pair
            if own is not None:
                own(run)
            else:
                STEPS[name](run, executor)
            resume()  # the garbage collector, after the first step at the latest (core.collector)
    return run


def _prepare(run: Run, ex) -> None:
    """Step 1: read the epochs into one working frame (:mod:`soilvolume.inputs.prepare`)."""
    run.hooks.step(run.at("prepare"), run.message("prepare") + ex.reading_note)
    with run.timer("crop"):
        ex.prepare(run)


def _register(run: Run, ex) -> None:
    """Step 2: the georeferencing decision, then coarse + fine registration."""
    from .steps import register_pair

    dense = ex.dense(run)
    progress = (*run.spans["register"], run.message("register"))
    run.reg, run.options = register_pair(run.prep, run.options, run.hooks, run.timer, dense, progress)
    fine = run.reg.fine
    run.hooks.info(f"coarse: {run.reg.coarse.note}")
    run.hooks.info(f"fine ({fine.method}): fitness {fine.fitness:.3f}, RMSE {fine.rmse:.3f} m, {fine.note}")


def _grid(run: Run, ex) -> None:
    """Step 3: the shared grid and each epoch's average heights on it."""
    run.hooks.step(run.at("grid"), run.message("grid"))
    with run.timer("grids"):
        ex.grid(run)


def _planes(run: Run, ex) -> None:
    """Step 4: the paper's planes and d_i (on the grid the volume step finds the correction on)."""
    from .steps import correction_step

    run.hooks.step(run.at("planes"), ex.correction_note(run) or correction_step(run.options))
    with run.timer("planes"):
        run.planes = ex.planes(run)


def _volume(run: Run, ex) -> None:
    """Step 5: difference, refill, correction, change areas, budgets, uncertainty, zones."""
    run.hooks.step(run.at("volume"), run.message("volume"))
    with run.timer("volume"):
        run.vols = ex.volume(run)


def _write(run: Run, ex) -> None:
    """Step 6: the rasters (and the registered cloud, when asked for)."""
    run.hooks.step(run.at("write"), run.message("write") + ex.raster_note)
    with run.timer("write"):
        ex.write(run)
        if run.command == "estimate" and run.options.contour_interval > 0:  # from the rasters just written
            staged = run.out.path(CONTOURS)
            run.contours = write_contours(staged, staged.parent, run.options.contour_interval)


def _report(run: Run, ex) -> None:
    """Step 7: the run's typed record, report.json (the quality verdict in it) and report.html."""
    from ..core.record import RunRecord
    from ..core.wording import cli_tree
    from ..reporting.report import build_report, write_json
    from .steps import quality_inputs, write_report_html

    run.hooks.step(run.at("report"), run.message("report"), log=False)
    with run.timer("report"):
        judged = quality_inputs(run.vols, ex.correction_grid(run)[0], run.options)
        p_b, p_a, _ = run.planes
        record = RunRecord(run.prep, run.reg, run.grid, (p_b, p_a), run.vols, run.options, judged, ex.engine(run))
        report = build_report(record, run.timer.totals())
        if run.contours:
            report["contours"] = run.contours
        for line in report["quality"]["messages"]:
            run.hooks.info(f"quality ({report['quality']['verdict']}): {line}")
        write_report_html(run.out, report, *ex.html(run))
        run.keyed, run.report = report, cli_tree(report)  # options by key; worded for the command line
        write_json(run.out.path("report.json"), run.report, run.timer.totals())


STEPS = {
    "prepare": _prepare,
    "register": _register,
    "grid": _grid,
    "planes": _planes,
    "volume": _volume,
    "write": _write,
    "report": _report,
}
