"""``soilvolume estimate DESIGN.tif AFTER.laz``: a survey against a surface (a grading plan or an
earlier DEM, :mod:`soilvolume.inputs.surface`). The estimate's steps without the before cloud:
nothing is registered against a surface, the surface is resampled onto the survey's grid as the
before DEM, and the volume step runs as for a pair (bias correction off unless asked); the
survey's agreement with the surface on unchanged ground joins the verdict (volumes/reference)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.hooks import Hooks, Result
from ..core.outputs import OutputDir
from ..core.types import GridSpec, SoilVolumeError, StageQuality
from ..dem import grid as gridmod
from ..inputs.prepare import Prepared
from ..inputs.surface import Surface, on_grid, read_surface, valid_box
from ..options import Options
from ..volumes import reference
from ..volumes.compute import Volumes
from .steps import Timer, write_report_html

NONE = "none: the reference is a surface"
NOT_REGISTERED = (
    f"registration: {NONE} (nothing is registered against a design: the survey must be well georeferenced; "
    "its agreement with the design on unchanged ground is checked)"
)
DESIGN_COUNT = 1000  # the points a surface cell stands for: never weak, never refilled as sparse
WORDING = {"fill": "above design", "cut": "below design", "net": "above minus below design"}


class _NoPlane:
    """The paper's planes do not apply to a surface: report.json's ``planes`` are null."""

    def as_dict(self, origin) -> None:
        return None


def estimate_surface(design: Path, after: Path, out: OutputDir, options: Options, timer: Timer, hooks: Hooks, pipe):
    """The run of :mod:`soilvolume.workflow.estimate` with a surface as the reference (``pipe``:
    the after cloud's PDAL pipeline)."""
    from ..inputs.prepare import prepare_survey
    from ..inputs.stream import open_source
    from ..volumes.compute import compute_volumes

    surface = read_surface(design, options.before_crs)  # before any point is read: bad rasters fail fast
    options = _options(options, hooks)
    hooks.step(2, f"reading {after.name} (the reference is the surface {design.name})")
    with timer("crop"):
        prep = prepare_survey(open_source(after, pipe), options, check=hooks.ticker(2, 15, "reading"))
    timer.s["read"], timer.s["crop"] = prep.read_s, timer.s["crop"] - prep.read_s
    prep = replace(prep, inputs={"before": surface.describe(), **prep.inputs})
    hooks.info(NOT_REGISTERED)
    hooks.step(55, f"gridding the survey and resampling {design.name} onto its grid")
    with timer("grids"):
        grid = survey_grid(prep, surface, options)
        dem_a = gridmod.epoch_dem(prep.after.xyz, grid, options.statistic, prep.after.nonsoil)
        dem_s, sigma = surface_epoch(surface, grid, options.design_uncertainty)
        _check_overlap(dem_a, dem_s, design, after)
    hooks.step(75, "computing the difference and volumes above and below the design")
    with timer("volume"):
        vols = compute_volumes(dem_a, dem_s, np.zeros((grid.rows, grid.cols)), grid, options)
        vols = _with_surface_terms(vols, sigma, options, grid)
    hooks.step(85, "writing outputs")
    with timer("write"):
        _write_rasters(out, vols, grid)
    with timer("report"):
        from ..reporting.report import write_json

        report = surface_report(prep, grid, vols, surface, options, timer)
        add_surface_quality(report, vols, grid, options, hooks)
        write_json(out.path("report.json"), report)
        write_report_html(out, report, vols, grid, dem_a.heights + grid.origin[2])
    return Result(report)


def _options(options: Options, hooks: Hooks) -> Options:
    """No bias correction against a design unless one is asked for (the default is refitted to
    none: a design is not the existing ground); the paper's planes need two clouds."""
    if options.correction == "paper-plane":
        raise SoilVolumeError(
            "--correction paper-plane needs two point clouds; against a surface: none (the default), plane, surface"
        )
    if options.keep_registered_cloud:
        hooks.info("--registered-cloud: nothing is registered against a surface, so no registered cloud is written")
    if options.correction == Options().correction:
        hooks.info("bias correction: none (the design is not the existing ground; --correction plane fits one)")
        return options.with_(correction="none", keep_registered_cloud=False)
    hooks.info(f"bias correction against the surface: {options.correction} on the unchanged ground, as asked")
    return options.with_(keep_registered_cloud=False)


def survey_grid(prep: Prepared, surface: Surface, options: Options) -> GridSpec:
    """The grid over the survey's footprint clipped to the surface's valid extent; the cell size
    from the survey's density unless ``--cell`` is given."""
    from ..inputs.footprint import footprint
    from ..validate import check_grid_cells

    thin, origin = prep.after_thin, prep.origin
    cell = options.cell
    if cell is None or cell <= 0:
        cell = gridmod.cell_for(prep.after.xyz, footprint(thin[:, :2]))
    box_lo, box_hi = valid_box(surface, prep.frame.crs, prep.frame.xy_unit)
    lo = np.maximum(thin[:, :2].min(axis=0), box_lo - origin[:2])
    hi = np.minimum(thin[:, :2].max(axis=0), box_hi - origin[:2])
    if (hi <= lo).any():
        raise SoilVolumeError(
            f"{surface.path} does not overlap {prep.after.path}: the surface's valid extent misses the survey "
            "(check the CRSs)"
        )
    grid = gridmod.make_grid(np.r_[lo, 0.0], np.r_[hi, 0.0], cell, origin, prep.frame.wkt, prep.frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    return grid


def surface_epoch(surface: Surface, grid: GridSpec, given_m: float) -> tuple[gridmod.EpochDEM, np.ndarray]:
    """(the surface as the before epoch on ``grid``, each cell's one-sigma error (m)): heights
    bilinear at the cell centres; the error of that resampling taken as its difference from a
    cubic one (it is where the surface curves between its own cells), with the given surface
    uncertainty ``given_m`` in quadrature. Each cell counts :data:`DESIGN_COUNT` points with that
    error as its standard error, so the per-cell level of detection includes it."""
    z = on_grid(surface, grid) - grid.origin[2]
    cubic = on_grid(surface, grid, "cubic") - grid.origin[2]
    valid = np.isfinite(z)
    sigma = np.where(valid, np.hypot(np.nan_to_num(np.abs(z - cubic)), given_m), np.nan)
    counts = np.where(valid, DESIGN_COUNT, 0).astype(np.int64)
    return gridmod.EpochDEM(z, counts, sigma * np.sqrt(DESIGN_COUNT)), sigma


def _check_overlap(dem_a: gridmod.EpochDEM, dem_s: gridmod.EpochDEM, design: Path, after: Path) -> None:
    if not (np.isfinite(dem_a.heights) & np.isfinite(dem_s.heights)).any():
        raise SoilVolumeError(f"{design} does not overlap {after}: no cell of the survey has a surface height")


def _with_surface_terms(vols: Volumes, sigma: np.ndarray, options: Options, grid: GridSpec) -> Volumes:
    """The volume step's result with the surface's resampling error and given uncertainty in its interval."""
    from ..volumes.uncertainty import bias_sigma, z_value

    u = vols.uncertainty
    cut = vols.cut_mask if vols.cut_mask is not None else np.zeros(sigma.shape, bool)
    counted = {"net": vols.change_mask, "cut": cut & vols.change_mask, "fill": vols.change_mask & ~cut}
    model = {"nugget": u["nugget_m2"], "psill": u["psill_m2"], "range": u["range_m"]}
    datum = bias_sigma(u["stable_cells"], grid.cell, model, 1) if options.correction == "none" else 0.0
    z = z_value(options.lod_confidence)
    terms = reference.design_terms(counted, sigma, options.design_uncertainty, datum, grid.cell_area, z)
    return replace(vols, uncertainty=reference.with_terms(vols.uncertainty, terms))


def _write_rasters(out: OutputDir, vols: Volumes, grid: GridSpec) -> None:
    """The estimate's rasters; dem_before.tif is the surface on the grid."""
    z0 = float(grid.origin[2])
    for name, key, desc in gridmod.output_layers("none"):
        array = getattr(vols, key)
        if key in gridmod.UINT8_LAYERS:
            gridmod.write_geotiff(out.path(name), array.astype("uint8"), grid, desc, "", "uint8")
            continue
        if key == "dem_b":
            desc = "the reference surface (design) resampled onto the grid, bilinear at the cell centres (m)"
        elif key == "diff":
            desc = "survey - design (m): above design > 0 (fill), below design < 0 (cut)"
        gridmod.write_geotiff(out.path(name), array + z0 if key.startswith("dem_") else array, grid, desc)


def surface_report(prep: Prepared, grid: GridSpec, vols: Volumes, surface: Surface, options: Options, timer) -> dict:
    """report.json of a run against a surface: an estimate's, with ``reference`` and no registration."""
    from ..registration.register import Registration
    from ..reporting.report import build_report

    stage = StageQuality(NONE, float("nan"), float("nan"), accepted=False, note=NONE)
    georef = {"requested": options.georeferencing, "used": "none", "reason": "the reference is a surface"}
    reg = Registration(np.eye(4), stage, stage, georef)
    report = build_report(prep, reg, grid, vols, _NoPlane(), _NoPlane(), options, timer)
    report["registration"]["kind"] = NONE
    report["reference"] = {**surface.describe(), "wording": WORDING, "uncertainty_m3": vols.uncertainty["reference_m3"]}
    report["volume_method"] = (
        "the survey against the reference surface (resampled onto the survey's grid): fill = the survey above "
        "the design, cut = below it, over the survey's footprint clipped to the design's valid extent; "
        + report["volume_method"]
    )
    return report


def add_surface_quality(report: dict, vols: Volumes, grid: GridSpec, options: Options, hooks: Hooks) -> None:
    """The verdict (volumes/quality) with the survey's agreement with the surface first, logged."""
    from ..compensation.correction import stable_cells
    from ..volumes.quality import assess

    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    q = assess(report, vols.stable, vols.change_mask, vols.offset, grid.cell_area, prior, vols.diff)
    unchanged = stable_cells(vols.diff, grid.cell)
    agree = reference.agreement(vols.diff, unchanged, vols.uncertainty["lod_m"], grid.cell_area)
    report["reference"]["agreement"] = agree
    report["quality"] = reference.merge(q, reference.check(agree))
    for line in report["quality"]["messages"]:
        hooks.info(f"quality ({report['quality']['verdict']}): {line}")
