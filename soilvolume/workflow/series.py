"""``soilvolume series E0 E1 ... En``: a site surveyed n + 1 times, E0 the reference.

A driver over the steps of :mod:`.steps` (the same ones an estimate run takes): each later epoch
is prepared and registered against E0 (the pair E0 -> Ek, so the stable-ground refinement works
on ground stable across the two), every epoch is moved into one frame (E0's, with the first
pair's local origin) and gridded on one grid (the cells every registered epoch covers), each
pair's volume step corrects Ek once relative to E0, and :mod:`soilvolume.volumes.series` turns
the corrected differences into periods that add up to the cumulative."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.hooks import Hooks, Result
from ..core.outputs import os_errors, output_dir
from ..core.types import GridSpec, SoilVolumeError
from ..dem import grid as gridmod
from ..inputs.footprint import footprint
from ..inputs.lasheader import creation_date
from ..inputs.prepare import Prepared
from ..options import Options
from ..registration.rigid import transform_points, transform_points32
from ..validate import check_grid_cells
from .steps import Timer, alternative_move, moved_nonsoil, planes_and_volumes, prepare_pair, register_pair


@dataclass(frozen=True)
class Fit:
    """A later epoch registered into E0's frame: its pair (rebased on the series origin), the
    registration (series frame) and the options its volume step takes (precise surveys: none)."""

    prep: Prepared
    reg: object
    options: Options


def epoch_dates(paths: list[Path], given: list[str] | None) -> list[str | None]:
    """Each epoch's date: ``given`` (``--dates``; an empty entry keeps the file's), else the
    LAS header's creation day and year, else None."""
    import datetime as dt

    if given is not None and len(given) != len(paths):
        raise SoilVolumeError(f"--dates: {len(given)} dates for {len(paths)} epochs (give one per epoch)")
    out = []
    for k, path in enumerate(paths):
        text = (given[k] if given else "").strip()
        if text:
            try:
                text = dt.date.fromisoformat(text).isoformat()
            except ValueError:
                raise SoilVolumeError(f"--dates: {text!r} is not a date (YYYY-MM-DD)") from None
        out.append(text or creation_date(path))
    return out


def check_epochs(paths: list[Path]) -> None:
    """At least two epochs, each an existing file or folder, none twice."""
    if len(paths) < 2:
        raise SoilVolumeError(f"series: {len(paths)} epoch given; at least two are needed (E0 and a later survey)")
    for path in paths:
        if not path.exists():
            raise SoilVolumeError(f"{path}: no such file")
    if len({p.resolve() for p in paths}) < len(paths):
        raise SoilVolumeError("series: an epoch is given twice")


def _scaled(hooks: Hooks, lo: float, hi: float) -> Hooks:
    """``hooks`` with the progress of a sub-run mapped from 0-100 onto ``lo``-``hi``."""
    show = hooks.progress
    progress = None if show is None else (lambda pct, msg: show(lo + (hi - lo) * pct / 100.0, msg))
    return Hooks(progress=progress, log=hooks.log, cancel=hooks.cancel)


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


def register_epoch(e0: Path, ek: Path, options: Options, hooks: Hooks, timer: Timer) -> Fit:
    """Prepare the pair E0 -> Ek and register Ek into E0's frame (the estimate's steps)."""
    with timer("crop"):
        prep = prepare_pair(e0, ek, options, hooks, None, None)
    reg, opts = register_pair(prep, options, hooks, timer, dense=(prep.after.xyz, prep.before.xyz))
    hooks.info(f"{ek.name}: fine ({reg.fine.method}) fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m")
    return Fit(prep, reg, opts)


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
    """See :func:`soilvolume.api.series`."""
    check_epochs(paths)
    when = epoch_dates(paths, dates)
    timer = Timer()
    with output_dir(out_dir, [*paths, options.stable_mask], overwrite) as out, os_errors(out.final):
        report = _series(paths, when, out, options, timer, hooks)
    hooks.step(100, "done")
    return Result(
        report, {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in out.moved.items()}
    )


def _series(paths, dates, out, options: Options, timer: Timer, hooks: Hooks) -> dict:
    from ..reporting.series import write_outputs
    from ..volumes.series import combine

    n = len(paths) - 1
    fits = []
    for k, path in enumerate(paths[1:], 1):
        hooks.step(60.0 * (k - 1) / n, f"epoch {k} of {n}: registering {path.name} into {paths[0].name}'s frame")
        fit = register_epoch(paths[0], path, options, _scaled(hooks, 60.0 * (k - 1) / n, 60.0 * k / n), timer)
        origin = fits[0].prep.origin if fits else np.asarray(fit.prep.origin, dtype=np.float64)
        fits.append(replace(fit, **dict(zip(("prep", "reg"), rebase(fit.prep, fit.reg, origin), strict=True))))
    hooks.step(62, f"gridding {n + 1} epochs on one grid")
    with timer("grids"):
        grid = series_grid(fits, options)
        e0 = fits[0].prep.before
        dems = [gridmod.epoch_dem(e0.xyz, grid, options.statistic, e0.nonsoil)]
        for f in fits:
            xyz = transform_points32(f.prep.after.xyz, f.reg.transform)
            dems.append(gridmod.epoch_dem(xyz, grid, options.statistic, moved_nonsoil(f.prep, f.reg)))
    hooks.step(70, "correcting each epoch once into E0's frame (bias on stable ground)")
    vols = []
    for k, f in enumerate(fits, 1):
        thin = transform_points(f.prep.after_thin, f.reg.transform)
        v, _, _ = planes_and_volumes(f.prep, f.reg, grid, dems[k], dems[0], thin, f.options, timer, Hooks())
        vols.append(v)
    hooks.step(85, "periods, cumulative and their intervals")
    with timer("series"):
        series = combine(vols, dems, [alternative_move(f.reg) for f in fits], grid, options)
    hooks.step(90, "writing outputs")
    with timer("write"):
        return write_outputs(out, paths, dates, fits, vols, series, grid, options, timer)
