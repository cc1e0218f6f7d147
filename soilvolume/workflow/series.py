"""``soilvolume series E0 E1 ... En``: a site surveyed n + 1 times, E0 the reference, as a run
of the one pipeline (:mod:`.run`, ``COMMAND_STEPS["series"]``) on the :class:`Series` executor.

Each later epoch is prepared and registered against E0 (the pair E0 -> Ek, so the stable-ground
refinement works on ground stable across the two) with the steps of :mod:`.steps` an estimate
takes, every epoch is moved into one frame (E0's, with the first pair's local origin) and
gridded on one grid (the cells every registered epoch covers), each pair's volume step corrects
Ek once relative to E0, and :mod:`soilvolume.volumes.series` turns the corrected differences
into periods that add up to the cumulative."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.hooks import Cancelled, Hooks, Result
from ..core.interrupt import Interrupted
from ..core.outputs import os_errors, output_dir
from ..core.types import Epoch, GridSpec, SoilVolumeError
from ..dem import grid as gridmod
from ..inputs.distinct import sameness
from ..inputs.footprint import footprint
from ..inputs.lasheader import creation_date
from ..inputs.prepare import Prepared
from ..options import Options
from ..registration.rigid import transform_points, transform_points32
from ..validate import check_grid_cells
from .timing import Timer


@dataclass(frozen=True)
class Fit:
    """A later epoch registered into E0's frame: its pair (rebased on the series origin), the
    registration (series frame) and the options its volume step takes (precise surveys: none)."""

    prep: Prepared
    reg: object
    options: Options


def epoch_dates(paths: list[Path], given: list[str] | None) -> list[tuple[str | None, str | None]]:
    """Each epoch's (date, where it came from): ``given`` (``--dates``; an empty entry keeps the
    file's), else the LAS header's creation day and year, else (None, None)."""
    import datetime as dt

    if given is not None and len(given) != len(paths):
        raise SoilVolumeError(f"--dates: {len(given)} dates for {len(paths)} epochs (give one per epoch)")
    out: list[tuple[str | None, str | None]] = []
    for k, path in enumerate(paths):
        text = (given[k] if given else "").strip()
        if text:
            try:
                out.append((dt.date.fromisoformat(text).isoformat(), "given"))
            except ValueError:
                raise SoilVolumeError(f"--dates: {text!r} is not a date (YYYY-MM-DD)") from None
            continue
        found = creation_date(path)
        out.append((found, "LAS header" if found else None))
    return out


def check_epochs(paths: list[Path]) -> None:
    """At least two epochs, each an existing file or folder."""
    if len(paths) < 2:
        raise SoilVolumeError(f"series: {len(paths)} epoch given; at least two are needed (E0 and a later survey)")
    for path in paths:
        if not path.exists():
            raise SoilVolumeError(f"{path}: no such file")


def described(epochs: tuple[Epoch, ...], k: int) -> str:
    """Epoch ``k`` in an error: its index, file and date with where the date came from."""
    e = epochs[k]
    source = {"LAS header": "from its LAS header", "given": "given by --dates"}.get(e.date_source or "", "")
    return f"E{k} {e.name} ({f'{e.date}, {source}' if e.date else 'no date'})"


def check_series(epochs: tuple[Epoch, ...]) -> None:
    """Every epoch a different survey (:func:`~soilvolume.inputs.distinct.sameness`), and the
    known dates in the order the epochs are given (a series is not reordered: E0 is the reference)."""
    for j, k in itertools.combinations(range(len(epochs)), 2):
        how = sameness(Path(epochs[j].path), Path(epochs[k].path))
        if how:
            raise SoilVolumeError(
                f"series: {described(epochs, k)} {how} {described(epochs, j)}; each epoch must be another survey"
            )
    latest = None  # the epoch of the latest date so far
    for k, e in enumerate(epochs):
        if not e.date:
            continue
        if latest is not None and e.date < epochs[latest].date:
            raise SoilVolumeError(
                f"series: the epochs are not in time order: {described(epochs, k)} is given after "
                f"{described(epochs, latest)}; give the surveys oldest first (E0 the reference) or correct "
                "their dates with --dates"
            )
        latest = k


@contextmanager
def naming(prefix: str) -> Iterator[None]:
    """A SoilVolumeError raised in the block with ``prefix`` (the epochs it concerns) before its
    message, its type and fields kept; an interruption as it is."""
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

    prep = replace(
        prep,
        before=cloud(prep.before),
        after=cloud(prep.after),
        origin=origin,
        before_thin=prep.before_thin + d,
        after_thin=prep.after_thin + d,
    )
    alt = reg.fine.alternative
    fine = reg.fine if alt is None else replace(reg.fine, alternative=_moved(alt, d))
    return prep, replace(reg, transform=_moved(reg.transform, d), fine=fine)


def series_grid(fits: list[Fit], options: Options) -> GridSpec:
    """One grid over the cells E0 and every registered later epoch cover (their boxes' overlap),
    cell size from E0's density (as :func:`.steps.shared_grid`)."""
    thins = [transform_points(f.prep.after_thin, f.reg.transform) for f in fits]
    prep = fits[0].prep
    lo = np.max([prep.before_thin.min(axis=0)] + [t.min(axis=0) for t in thins], axis=0)
    hi = np.min([prep.before_thin.max(axis=0)] + [t.max(axis=0) for t in thins], axis=0)
    if (hi[:2] <= lo[:2]).any():
        raise SoilVolumeError("the registered epochs have no area in common with each other and E0")
    cell = options.cell
    if cell is None or cell <= 0:
        cell = gridmod.cell_for(prep.before.xyz, footprint(thins[0][:, :2]))
    grid = gridmod.make_grid(lo, hi, cell, prep.origin, prep.frame.wkt, prep.frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    return grid


def run_series(
    paths: list[Path], out_dir: Path, options: Options, *, dates=None, overwrite: bool, hooks: Hooks
) -> Result:
    """See :func:`soilvolume.api.series`: the pipeline of :mod:`.run` over E0 and every later epoch."""
    from .run import Run, drive

    timer = Timer()
    check_epochs(paths)
    dated = zip(paths, epoch_dates(paths, dates), strict=True)
    epochs = tuple(Epoch(p, date=d, date_source=source) for p, (d, source) in dated)
    check_series(epochs)
    with output_dir(out_dir, [*paths, options.stable_mask], overwrite) as out, os_errors(out.final):
        run = drive(Run("series", epochs, options, hooks, timer, out=out), Series())
    hooks.step(100, "done")
    moved = out.moved.items()
    return Result(run.report, {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in moved})


def pair_named(run, k: int) -> str:
    """The pair E0 -> Ek of a series in an error."""
    return f"{described(run.epochs, k)} against {described(run.epochs, 0)}"


class Series:
    """The executor of a series run (in-process): each step's work over E0 and every later epoch.
    ``prepare``: the pairs E0 -> Ek; ``register_step``: each Ek into E0's frame, rebased on one
    local origin; ``grid``: one grid, every epoch's DEM; ``planes_step``: each pair's planes;
    ``volume``: each pair's volume step (Ek corrected once relative to E0), then the periods
    (:func:`soilvolume.volumes.series.combine`); ``write``; ``report_step``."""

    reading_note = ""
    raster_note = ""

    def __init__(self) -> None:
        self.preps: list[Prepared] = []
        self.fits: list[Fit] = []
        self.vols: list = []
        self.planes: list = []

    @contextmanager
    def session(self, run):
        yield self

    def _each(self, run, step: str, k: int, n: int) -> tuple[float, float]:
        lo, hi = run.spans[step]
        return lo + (hi - lo) * k / n, lo + (hi - lo) * (k + 1) / n

    def prepare(self, run) -> None:
        from .steps import prepare_pair

        e0, later = run.epochs[0], run.epochs[1:]
        for k, ek in enumerate(later):
            spans = {"prepare": self._each(run, "prepare", k, len(later))}
            with naming(pair_named(run, k + 1)):
                self.preps.append(prepare_pair(e0.path, ek.path, run.options, run.hooks, None, None, spans))

    def register_step(self, run) -> None:
        from .steps import register_pair

        n, seconds = len(self.preps), {"coarse": 0.0, "fine": 0.0, "register_other": 0.0}
        for k, prep in enumerate(self.preps):
            name = run.epochs[k + 1].name
            progress = (*self._each(run, "register", k, n), f"registering {name} into {run.epochs[0].name}'s frame")
            with naming(pair_named(run, k + 1)):
                dense = (prep.after.xyz, prep.before.xyz)
                reg, opts = register_pair(prep, run.options, run.hooks, run.timer, dense, progress)
            run.hooks.info(
                f"{name}: fine ({reg.fine.method}) fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m"
            )
            seconds = {s: t + run.timer.s[s] for s, t in seconds.items()}
            if self.fits:  # E0's DEM comes from the first pair: later pairs keep E0's subsets only
                prep = replace(prep, before=replace(prep.before, xyz=prep.before.xyz[:0], nonsoil=None))
            origin = self.fits[0].prep.origin if self.fits else np.asarray(prep.origin, dtype=np.float64)
            self.fits.append(Fit(*rebase(prep, reg, origin), opts))
        run.timer.s.update(seconds)
        self.preps = []  # the fits hold them now

    def grid(self, run) -> None:
        from .steps import moved_nonsoil

        with naming("series " + ", ".join(described(run.epochs, k) for k in range(len(run.epochs)))):
            grid = run.grid = series_grid(self.fits, run.options)
        e0 = self.fits[0].prep.before
        dems = [gridmod.epoch_dem(e0.xyz, grid, run.options.statistic, e0.nonsoil)]
        for f in self.fits:
            xyz = transform_points32(f.prep.after.xyz, f.reg.transform)
            dems.append(gridmod.epoch_dem(xyz, grid, run.options.statistic, moved_nonsoil(f.prep, f.reg)))
        run.dems = tuple(dems)

    def planes_step(self, run) -> None:
        from .steps import correction_step, planes_step

        run.hooks.step(run.at("planes"), correction_step(run.options) + ", each epoch once relative to E0")
        with run.timer("planes"):
            for k, f in enumerate(self.fits, 1):
                thin = transform_points(f.prep.after_thin, f.reg.transform)
                with naming(pair_named(run, k)):
                    self.planes.append(planes_step(f.prep, run.grid, run.dems[0], thin, f.options))

    def volume(self, run):
        from ..volumes.series import combine
        from .steps import alternative_move, volume_step

        for k, (f, planes) in enumerate(zip(self.fits, self.planes, strict=True), 1):
            with naming(pair_named(run, k)):
                self.vols.append(volume_step((run.dems[k], run.dems[0]), planes[2], run.grid, f.options, f.reg))
        run.hooks.step(run.at("volume", 0.8), "periods, cumulative and their intervals")
        moves = [alternative_move(f.reg) for f in self.fits]
        return combine(self.vols, list(run.dems), moves, run.grid, run.options)

    def write(self, run) -> None:
        from ..reporting.series import write_rasters

        write_rasters(
            run.out, run.vols, self.vols[0].dem_out_b, run.grid
        )  # E0 refilled: the DEMs give back the differences

    def report_step(self, run) -> None:
        from ..reporting.series import write_reports

        run.hooks.step(run.at("report"), run.message("report"), log=False)
        with run.timer("report"):
            args = (run.epochs, self.fits, self.vols, run.vols, run.grid, run.options, run.timer)
            run.report = write_reports(run.out, *args)
