"""``soilvolume estimate DESIGN.tif AFTER.laz``: a survey against a surface (a grading plan or an
earlier DEM, :mod:`soilvolume.inputs.surface`). The estimate's steps without the before cloud:
nothing is registered against a surface, the surface is resampled onto the survey's grid as the
before DEM, and the volume step runs as for a pair (bias correction off unless asked); the
survey's agreement with the surface on unchanged ground leads the verdict (volumes/reference,
through reporting/surface)."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..core.record import Georeferencing
from ..core.types import GridSpec, SoilVolumeError, StageQuality
from ..dem import grid as gridmod
from ..dem.geotiff import write_grid
from ..inputs.heights import masked_notes
from ..inputs.landxml import Tin
from ..inputs.prepare import Prepared
from ..inputs.surface import Surface, SurfaceSource, on_grid, open_surface, read_over, valid_box
from ..options import Options
from ..reporting.surface import NONE
from ..volumes import reference
from ..volumes.compute import Volumes

NOT_REGISTERED = (
    f"registration: {NONE} (nothing is registered against a design: the survey must be well georeferenced; "
    "its agreement with the design on unchanged ground is checked)"
)
DESIGN_COUNT = 1000  # the points a surface cell stands for: never weak, never refilled as sparse


class _NoPlane:
    """The paper's planes do not apply to a surface: report.json's ``planes`` are null."""

    def as_dict(self, origin) -> None:
        return None


class SurfaceReference:
    """The executor of an estimate whose reference is a surface (see module): the run's steps
    are :data:`soilvolume.workflow.run.COMMAND_STEPS` ``["surface"]``, without register and
    planes; the survey's point work is in-process."""

    reading_note = " (the reference is a surface)"
    raster_note = ""

    def __init__(self) -> None:
        self.surface: Surface | Tin | None = None
        self.cell = 0.0
        self.sigma: np.ndarray | None = None

    @contextmanager
    def session(self, run):
        yield self

    def prepare(self, run) -> None:
        """The surface opened and checked (before any point), then the survey alone, then the
        surface's heights over the survey's box; nothing registered."""
        from ..inputs.prepare import prepare_survey
        from ..pipelines.pipeline import open_source
        from ..registration.register import Registration

        design, after = run.epochs
        source = open_surface(Path(design.path), run.options.before_crs, run.options.design_surface)
        run.options = _options(run.options, run.hooks)
        check = run.hooks.ticker(*run.spans["prepare"], "reading")
        prep = prepare_survey(open_source(after.path, after.pipeline), run.options, check=check)
        run.timer.s["read"] = prep.read_s
        run.timer.s["crop"] = run.timer.s.get("crop", 0.0) - prep.read_s
        self.cell = survey_cell(prep, run.options)
        self.surface = _read_surface(source, prep, self.cell, run.hooks)
        run.prep = replace(prep, inputs={"before": self.surface.describe(), **prep.inputs})
        stage = StageQuality(NONE, float("nan"), float("nan"), accepted=False, note=NONE)
        georef = Georeferencing(run.options.georeferencing, "none", "the reference is a surface")
        run.reg = Registration(np.eye(4), stage, stage, georef)
        run.hooks.info(NOT_REGISTERED)

    def grid(self, run) -> None:
        """The survey's grid clipped to the surface, its DEM, and the surface resampled onto it."""
        prep = run.prep
        run.after_thin = prep.after_thin
        grid = run.grid = survey_grid(prep, self.surface, self.cell)
        dem_a = gridmod.epoch_dem(prep.after.xyz, grid, run.options.statistic, prep.after.nonsoil)
        dem_s, self.sigma = surface_epoch(self.surface, grid, run.options.design_uncertainty)
        _check_overlap(dem_a, dem_s, self.surface.path, prep.after.path)
        run.dems = (dem_a, dem_s)
        run.planes = (_NoPlane(), _NoPlane(), np.zeros((grid.rows, grid.cols)))

    def correction_grid(self, run) -> tuple:
        return run.grid, run.dems

    def volume(self, run) -> Volumes:
        from ..volumes.compute import compute_volumes

        vols = compute_volumes(run.dems[0], run.dems[1], run.planes[2], run.grid, run.options)
        return reference.with_surface(vols, self.sigma, run.options, run.grid)

    def write(self, run) -> None:
        _write_rasters(run.out, run.vols, run.grid)

    def engine(self, run) -> dict | None:
        return None

    def html(self, run) -> tuple:
        return run.vols, run.grid, run.dems[0].heights + run.grid.origin[2]


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


def survey_cell(prep: Prepared, options: Options) -> float:
    """The grid's cell: ``--cell``, else from the survey's density."""
    from ..inputs.footprint import footprint

    if options.cell is not None and options.cell > 0:
        return options.cell
    return gridmod.cell_for(prep.after.xyz, footprint(prep.after_thin[:, :2]))


def _read_surface(source: SurfaceSource | Tin, prep: Prepared, cell: float, hooks: Hooks) -> Surface | Tin:
    """The surface's heights over the survey's box and two cells around it (the grid's edges
    and the resampling's kernel): a design far larger than the site costs only the site's window."""
    thin, origin = prep.after_thin[:, :2], prep.origin[:2]
    surface = read_over(source, thin.min(axis=0) + origin, thin.max(axis=0) + origin, prep.frame, 2 * cell)
    for note in masked_notes(source.path, surface.masked):
        hooks.info(note)
    return surface


def survey_grid(prep: Prepared, surface: Surface | Tin, cell: float) -> GridSpec:
    """The grid of ``cell`` over the survey's footprint clipped to the surface's valid extent."""
    from ..validate import check_grid_cells

    thin, origin = prep.after_thin, prep.origin
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


def surface_epoch(surface: Surface | Tin, grid: GridSpec, given_m: float) -> tuple[gridmod.EpochDEM, np.ndarray]:
    """(the surface as the before epoch on ``grid``, each cell's one-sigma error (m)): heights
    bilinear at the cell centres; the error of that resampling taken as its difference from a
    cubic one (it is where the surface curves between its own cells), with the given surface
    uncertainty ``given_m`` in quadrature. Each cell counts :data:`DESIGN_COUNT` points with that
    error as its standard error, so the per-cell level of detection includes it."""
    z = on_grid(surface, grid) - grid.origin[2]
    cubic = z if isinstance(surface, Tin) else on_grid(surface, grid, "cubic") - grid.origin[2]  # a TIN is exact
    valid = np.isfinite(z)
    sigma = np.where(valid, np.hypot(np.nan_to_num(np.abs(z - cubic)), given_m), np.nan)
    counts = np.where(valid, DESIGN_COUNT, 0).astype(np.int64)
    return gridmod.EpochDEM(z, counts, sigma * np.sqrt(DESIGN_COUNT)), sigma


def _check_overlap(dem_a: gridmod.EpochDEM, dem_s: gridmod.EpochDEM, design: Path, after: Path) -> None:
    if not (np.isfinite(dem_a.heights) & np.isfinite(dem_s.heights)).any():
        raise SoilVolumeError(f"{design} does not overlap {after}: no cell of the survey has a surface height")


def _write_rasters(out: OutputDir, vols: Volumes, grid: GridSpec) -> None:
    """The estimate's rasters; dem_before.tif is the surface on the grid."""
    z0 = float(grid.origin[2])
    for name, key, desc in gridmod.output_layers("none"):
        array = getattr(vols, key)
        if key in gridmod.UINT8_LAYERS:
            write_grid(out.path(name), array.astype("uint8"), grid, desc, "", "uint8")
            continue
        if key == "dem_out_b":
            desc = "the reference surface (design) resampled onto the grid, bilinear at the cell centres (m)"
        elif key == "diff":
            desc = "survey - design (m): above design > 0 (fill), below design < 0 (cut)"
        write_grid(out.path(name), array + z0 if key.startswith("dem_") else array, grid, desc)
