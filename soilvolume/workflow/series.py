"""``soilvolume series E0 E1 ... En``: the method's steps over the pairs E0 -> Ek (each registered on ground
stable between the two), in memory: every epoch in E0's frame on one grid, each Ek corrected once relative
to E0, the periods adding up to the cumulative (:mod:`soilvolume.volumes.series`)."""

from __future__ import annotations

import datetime as dt
import itertools
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..compensation.planes import plane_offset
from ..core.hooks import Cancelled, Hooks, Result
from ..core.interrupt import Interrupted
from ..core.outputs import os_errors, output_dir
from ..core.types import Epoch, GridSpec, SoilVolumeError, survey
from ..dem.grid import epoch_dem
from ..execution.inmemory import InMemory
from ..inputs.footprint import footprint
from ..inputs.io import sameness
from ..inputs.lasheader import creation_date
from ..inputs.prepare import Prepared
from ..options import Options
from ..registration.register import Registration
from ..registration.rigid import transform_points, transform_points32
from ..reporting.series import write_rasters, write_reports
from ..validate import schedule_of
from ..volumes.series import combine
from . import steps
from .context import PAIR, Context, Timer, threads
from .plan import plan_grid, reference_cell
from .seriesgrade import grade_epochs, open_design


@dataclass(frozen=True)
class Fit:
    """A later epoch registered into E0's frame: its pair and registration rebased on the series
    origin, and the options its volume step takes (precise surveys: no correction)."""

    prep: Prepared
    reg: Registration
    options: Options


def described(epochs: tuple[Epoch, ...], k: int) -> str:
    """Epoch ``k`` in an error: its index, file and date with where the date came from."""
    e = epochs[k]
    source = {"LAS header": "from its LAS header", "given": "given by --dates"}.get(e.date_source or "", "")
    return f"E{k} {e.name} ({f'{e.date}, {source}' if e.date else 'no date'})"


def series_epochs(paths: list[Path], dates: list[str] | None, options: Options) -> tuple[Epoch, ...]:
    """The epochs of a series (at least two, each an existing file or folder), each dated by ``--dates``
    (empty keeps the file's), else by its LAS header, else not; checked (:func:`check_series`)."""
    if len(paths) < 2:
        raise SoilVolumeError(f"series: {len(paths)} epoch given; at least two are needed (E0 and a later survey)")
    for path in paths:
        if not path.exists():
            raise SoilVolumeError(f"{path}: no such file")
    if dates is not None and len(dates) != len(paths):
        raise SoilVolumeError(f"--dates: {len(dates)} dates for {len(paths)} epochs (give one per epoch)")
    epochs = []
    for path, text in zip(paths, [d.strip() for d in dates or [""] * len(paths)], strict=True):
        try:
            date = dt.date.fromisoformat(text).isoformat() if text else creation_date(path)
        except ValueError:
            raise SoilVolumeError(f"--dates: {text!r} is not a date (YYYY-MM-DD)") from None
        source = None if date is None else "given" if text else "LAS header"
        epochs.append(survey(path, crs=None, date=date, date_source=source, georeferencing=options.georeferencing))
    check_series(tuple(epochs))
    return tuple(epochs)


def check_series(epochs: tuple[Epoch, ...]) -> None:
    """Every epoch another survey (:func:`~soilvolume.inputs.io.sameness`), the known dates in
    the epochs' order (a series is not reordered: E0 is the reference)."""
    for j, k in itertools.combinations(range(len(epochs)), 2):
        how = sameness(Path(epochs[j].path), Path(epochs[k].path))
        if how:
            raise SoilVolumeError(
                f"series: {described(epochs, k)} {how} {described(epochs, j)}; each epoch must be another survey"
            )
    dated = [k for k, e in enumerate(epochs) if e.date]
    for latest, k in itertools.pairwise(dated):
        if epochs[k].date < epochs[latest].date:
            raise SoilVolumeError(
                f"series: the epochs are not in time order: {described(epochs, k)} is given after "
                f"{described(epochs, latest)}; give the surveys oldest first (E0 the reference) or correct "
                "their dates with --dates"
            )


@contextmanager
def naming(prefix: str) -> Iterator[None]:
    """A SoilVolumeError of the block prefixed with ``prefix`` (its epochs), its type kept; not an interruption."""
    try:
        yield
    except (Interrupted, Cancelled):
        raise
    except SoilVolumeError as exc:
        exc.args = (f"{prefix}: {exc.keyed}", *exc.args[1:])
        raise


def _moved(t: np.ndarray, d: np.ndarray) -> np.ndarray:
    """A local transform of a frame with origin ``o + d`` re-expressed with origin ``o``."""
    s = np.eye(4)
    s[:3, 3] = d
    return s @ t @ np.linalg.inv(s)


def rebase(prep: Prepared, reg, origin: np.ndarray) -> tuple[Prepared, object]:
    """The pair and its registration with the local origin ``origin`` (same frame, same CRS)."""
    d = np.asarray(prep.origin, dtype=np.float64) - origin
    if not d.any():
        return prep, reg

    def cloud(c):
        ns = c.nonsoil
        ns = None if ns is None else replace(ns, xyz=(ns.xyz + d).astype(ns.xyz.dtype))
        return replace(c, xyz=(c.xyz + d).astype(c.xyz.dtype), origin=origin, nonsoil=ns)

    thin = {"before_thin": prep.before_thin + d, "after_thin": prep.after_thin + d}
    prep = replace(prep, before=cloud(prep.before), after=cloud(prep.after), origin=origin, **thin)
    alt = reg.fine.alternative
    fine = reg.fine if alt is None else replace(reg.fine, alternative=_moved(alt, d))
    return prep, replace(reg, transform=_moved(reg.transform, d), fine=fine)


def run_series(
    epochs: list[str | Path],
    out_dir: str | Path,
    options: Options | None = None,
    *,
    dates: list[str] | None = None,
    overwrite: bool = False,
    hooks: Hooks | None = None,
) -> Result:
    """Volume change over surveys (``api.series``), E0 the reference: report.json's ``epochs``, ``periods`` and
    ``cumulative`` (the periods' nets add up to it); ``dates``: one per epoch (YYYY-MM-DD; empty: the file's)."""
    paths, options, hooks = [Path(e) for e in epochs], options or Options(), hooks or Hooks()
    timer = Timer()
    schedule = schedule_of(options)  # parsed once, before any work (a series runs in this process)
    epochs = series_epochs(paths, dates, options)
    design = open_design(options)  # checked before any point is read
    threads(options)
    inputs = [*paths, options.stable_mask, options.design, options.zones]
    with output_dir(Path(out_dir), inputs, overwrite) as out, os_errors(out.final):
        ctx = Context(epochs, options.with_(zones=None), hooks, PAIR, timer, out, schedule=schedule)
        report = series(ctx, InMemory(), design)
    hooks.step(100, "done")
    return Result.written(report, out.moved)


def pair_named(ctx: Context, k: int) -> str:
    """The pair E0 -> Ek of a series in an error."""
    return f"{described(ctx.epochs, k)} against {described(ctx.epochs, 0)}"


def series(ctx: Context, backend: InMemory, design=None) -> dict:
    """Read and register each pair E0 -> Ek, grid every epoch on one grid, each pair's planes and volume
    step, the periods, each epoch against the ``design`` (:func:`.seriesgrade.open_design`), write, report."""
    with backend.session(ctx):
        with steps.running(ctx, "prepare", ctx.message("prepare"), "crop"):
            preps = [_read(ctx, backend, k) for k in range(1, len(ctx.epochs))]
        fits = _register(ctx, preps)
        del preps
        with steps.running(ctx, "grid", ctx.message("grid"), "grids"):
            grid, dems = _grid(ctx, fits)
        fitted = _planes(ctx, fits, grid, dems)
        with steps.running(ctx, "volume", ctx.message("volume")):
            vols = []  # each pair's volume step on the whole grid: Ek corrected once relative to E0
            for k, (f, planes) in enumerate(zip(fits, fitted, strict=True), 1):
                with naming(pair_named(ctx, k)):
                    vols.append(steps.volume_step(f.reg, f.options)(dems[k], dems[0], planes[2], grid))
            ctx.hooks.step(ctx.at("volume", 0.8), "periods, cumulative and their intervals")
            combined = combine(vols, list(dems), [steps.alternative_move(f.reg) for f in fits], grid, ctx.options)
            heights = [vols[0].dem_out_b + d for d in combined.to_e0]  # as dem_epoch<k>.tif, local
            graded = None if design is None else grade_epochs(design, heights, grid, fits[0].prep.frame)
        with steps.running(ctx, "write", ctx.message("write")):
            # E0 refilled: the DEMs give back the differences
            write_rasters(ctx.out, combined, vols[0].dem_out_b, grid, graded)
        with steps.running(ctx, "report", ctx.message("report"), log=False):
            return write_reports(ctx.out, ctx.epochs, fits, vols, combined, grid, ctx.options, ctx.timer, graded)


def _read(ctx: Context, backend: InMemory, k: int) -> Prepared:
    """The pair E0 -> Ek read (progress within its share of the step)."""
    n = len(ctx.epochs) - 1
    spans = {**ctx.spans, "prepare": (ctx.at("prepare", (k - 1) / n), ctx.at("prepare", k / n))}
    with naming(pair_named(ctx, k)):
        return backend.read(replace(ctx, epochs=(ctx.epochs[0], ctx.epochs[k]), spans=spans))


def _register(ctx: Context, preps: list[Prepared]) -> list[Fit]:
    """Each Ek registered into E0's frame (on ground stable between the two), rebased on the
    first pair's local origin; E0's DEM comes from the first pair: later pairs keep E0's subsets."""
    n, seconds, fits = len(preps), {"coarse": 0.0, "fine": 0.0, "register_other": 0.0}, []
    for k, prep in enumerate(preps):
        name = ctx.epochs[k + 1].name
        span = (ctx.at("register", k / n), ctx.at("register", (k + 1) / n))
        progress = (*span, f"registering {name} into {ctx.epochs[0].name}'s frame")
        with naming(pair_named(ctx, k + 1)):
            reg, opts = steps.register(ctx, prep, (prep.after.xyz, prep.before.xyz), progress)
        ctx.hooks.info(f"{name}: fine ({reg.fine.method}) fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m")
        seconds = {s: t + ctx.timer.s[s] for s, t in seconds.items()}
        if fits:
            prep = replace(prep, before=replace(prep.before, xyz=prep.before.xyz[:0], nonsoil=None))
        origin = fits[0].prep.origin if fits else np.asarray(prep.origin, dtype=np.float64)
        fits.append(Fit(*rebase(prep, reg, origin), opts))
    ctx.timer.s.update(seconds)
    return fits


def _grid(ctx: Context, fits: list[Fit]) -> tuple[GridSpec, tuple]:
    """One grid over the overlap of E0's and every registered epoch's boxes (:mod:`.plan`), every epoch's DEM
    on it (E0 first)."""
    thins = [transform_points(f.prep.after_thin, f.reg.transform) for f in fits]
    prep, names = fits[0].prep, ", ".join(described(ctx.epochs, k) for k in range(len(ctx.epochs)))
    with naming("series " + names):  # the cell from E0's points within the first registered epoch's footprint
        cell = reference_cell(prep, footprint(thins[0][:, :2]), ctx.options)
        empty = "the registered epochs have no area in common with each other and E0"
        grid = plan_grid(cell, [prep.before_thin, *thins], prep.origin, prep.frame, empty)
    e0, statistic = fits[0].prep.before, ctx.options.statistic
    dems = [epoch_dem(e0.xyz, grid, statistic, e0.nonsoil)]
    for f in fits:
        nonsoil = None if f.prep.after.nonsoil is None else f.prep.after.nonsoil.moved(f.reg.transform)
        dems.append(epoch_dem(transform_points32(f.prep.after.xyz, f.reg.transform), grid, statistic, nonsoil))
    return grid, tuple(dems)


def _planes(ctx: Context, fits: list[Fit], grid: GridSpec, dems: tuple) -> list[tuple]:
    """Each pair's planes and d_i, each epoch once relative to E0."""
    message = steps.correction_message(ctx.options) + ", each epoch once relative to E0"
    out = []
    with steps.running(ctx, "planes", message):
        for k, f in enumerate(fits, 1):
            thin = transform_points(f.prep.after_thin, f.reg.transform)
            with naming(pair_named(ctx, k)):
                p_b, p_a = steps.fit_planes(f.prep, thin, f.options)(grid, dems[0])
                out.append((p_b, p_a, plane_offset(p_b, p_a, grid)))
    return out
