"""The pieces of the steps both executors share (:mod:`.executors`, the tiled
:mod:`soilvolume.distributed.executor`): reading the pair, registration with its
georeferencing decision, the shared grid, the planes, the volume step, the quality verdict,
report.html. The order they run in is :mod:`.run`'s."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..core.cells import bounds
from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..core.record import Georeferencing, QualityInputs
from ..core.types import GridSpec, SoilVolumeError
from ..core.wording import opt
from ..dem import grid as gridmod
from ..inputs.footprint import footprint
from ..inputs.prepare import Prepared, prepare
from ..options import Options
from ..validate import check_grid_cells

if TYPE_CHECKING:  # the volume step's modules (SciPy's ndimage) are not needed to read the pair
    from ..volumes.compute import Volumes


def shared_grid(prep: Prepared, after_thin: np.ndarray, options: Options, poly: np.ndarray | None = None) -> GridSpec:
    """The grid over the registered after footprint (``poly``, when the caller has it), cell size
    from the before density."""
    poly = footprint(after_thin[:, :2]) if poly is None else poly
    cell = options.cell
    if cell is None or cell <= 0:
        cell = gridmod.cell_for(prep.before.xyz, poly)
    (lo_a, hi_a), (lo_b, hi_b) = bounds(after_thin, 2), bounds(prep.before_thin, 2)  # x/y: the grid's
    lo, hi = np.maximum(lo_a, lo_b), np.minimum(hi_a, hi_b)
    if (hi <= lo).any():
        raise SoilVolumeError("the registered after cloud does not overlap the before cloud")
    grid = gridmod.make_grid(lo, hi, cell, prep.origin, prep.frame.wkt, prep.frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    return grid


def prepare_pair(before, after, options: Options, hooks: Hooks, before_pipeline, after_pipeline, spans) -> Prepared:
    """Both clouds read whole (:func:`inputs.prepare.prepare`), progress within ``spans["prepare"]``."""
    from ..pipelines.pipeline import open_source

    src_b, src_a = open_source(before, before_pipeline), open_source(after, after_pipeline)
    return prepare(src_b, src_a, options, check=hooks.ticker(*spans["prepare"], "reading"))


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
    """report.html, and the areas of significant change as polygons (its map outlines them)."""
    from ..reporting.changeareas import FILE, write_change_areas

    write_change_areas(out.path(FILE), vols.diff, vols.change_mask, vols.cut_mask, grid)
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
        "change": vols.change_mask,
    }
    write_html(report, arrays, grid, out.path("report.html"))


def planes_step(prep: Prepared, grid: GridSpec, dem_before: gridmod.EpochDEM, after_thin: np.ndarray, options):
    """The paper's two RANSAC planes (before on its valid cells, registered after) and d_i per
    cell: (plane before, plane after, d_i). The after plane is found on a second thread meanwhile
    (its matrix products and counts release the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        after = pool.submit(after_plane, after_thin, options)
        return with_offset(before_plane(prep, grid, dem_before, options), after.result(), grid)


def before_plane(prep: Prepared, grid: GridSpec, dem_before: gridmod.EpochDEM, options):
    """The before cloud's RANSAC plane, on its thinned points over the cells it has heights in."""
    from ..compensation import planes

    sel_b = points_on(prep.before_thin, grid, np.isfinite(dem_before.heights))
    return planes.ransac_plane(sel_b, options.plane_threshold, seed=options.seed)


def after_plane(after_thin: np.ndarray, options):
    """The registered after cloud's RANSAC plane."""
    from ..compensation import planes

    return planes.ransac_plane(after_thin, options.plane_threshold, seed=options.seed + 1)


def with_offset(p_b, p_a, grid: GridSpec) -> tuple:
    """(plane before, plane after, d_i on ``grid``)."""
    from ..compensation import planes

    return p_b, p_a, planes.plane_offset(p_b, p_a, grid)


def volume_step(dems: tuple, d_i: np.ndarray, grid: GridSpec, options: Options, reg) -> Volumes:
    """The volume step (:func:`volumes.compute.compute_volumes`) on the (after, before) DEMs."""
    from ..volumes.compute import compute_volumes

    return compute_volumes(dems[0], dems[1], d_i, grid, options, moved=alternative_move(reg))


def correction_step(options: Options) -> str:
    """The progress message of the correction step: what it does with these options."""
    if options.correction == "none":
        return "comparing the surfaces (no vertical bias correction)"
    return "estimating the vertical bias correction"


def alternative_move(reg) -> np.ndarray | None:
    """The rigid move (4x4, local) from the accepted pose to the nearly as good one (None)."""
    alt = reg.fine.alternative
    return None if alt is None else alt @ np.linalg.inv(reg.transform)


def quality_inputs(vols: Volumes, grid: GridSpec, options: Options) -> QualityInputs:
    """What the quality verdict judges of a run, on ``grid`` (the correction's)."""
    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    return QualityInputs(vols.stable, vols.change_mask, vols.offset, vols.diff, grid.cell_area, prior)


def register_pair(prep: Prepared, options: Options, hooks: Hooks, timer, dense, progress: tuple):
    """Decide how far the georeferencing is trusted, then register: (Registration, the options
    the rest of the run uses; precise surveys get no bias correction). Auto with a vertical datum
    both files declare registers first and keeps the coordinates only when the registration
    confirms them (:func:`soilvolume.registration.georef.confirm`). ``register_other`` in the
    timings: the decision and the imports, beside the coarse and fine stages."""
    with timer("register"):
        from ..registration import georef
        from ..registration.register import register

        lo, hi, message = progress  # the run's span and message of the step (workflow/run.PROGRESS)
        hooks.step(lo, message)
        after, before = prep.after_thin, prep.before_thin
        decided, check = georef.declared(options.georeferencing, prep.inputs), None
        mode, why = decided or ("gps", "")
        ticker = hooks.ticker(lo, hi, message)
        reg = ran = register(after, before, options, check=ticker, dense=dense, precise=mode == "precise")
        if decided is None:
            datum = georef.vertical_datum(prep.inputs["after"].get("crs_wkt"))
            mode, why, check = georef.confirm(reg, after, before, datum, options.fine)
            if mode == "precise":
                reg = kept_as_georeferenced(register(after, before, options, precise=True), check["outcome"])
        hooks.info(f"georeferencing: {mode} ({why})")
        if mode == "precise":
            options = options.with_(correction="none")
    reg = replace(reg, georeferencing=Georeferencing(options.georeferencing, mode, why, check))
    timer.s["coarse"], timer.s["fine"] = ran.coarse.seconds, ran.fine.seconds
    timer.s["register_other"] = max(0.0, timer.s.pop("register") - ran.coarse.seconds - ran.fine.seconds)
    return reg, options


def kept_as_georeferenced(reg, outcome: str):
    """The identity registration of coordinates auto kept, its stages saying why."""
    said = "confirmed them" if outcome == "confirmed" else "could not confirm them"
    note = f"not applied: coordinates used as georeferenced (the registration {said}; see {opt('georeferencing')})"
    return replace(reg, coarse=replace(reg.coarse, note=note), fine=replace(reg.fine, note=note))
