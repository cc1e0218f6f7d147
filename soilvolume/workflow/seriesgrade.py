"""``soilvolume series E0 ... En --design DESIGN --tolerance T``: progress against a design. The design (a DEM
GeoTIFF or a LandXML TIN) is checked before any point is read, resampled onto the series' grid, and each
epoch's corrected DEM graded against it (:func:`soilvolume.volumes.grade.grade`): its share on grade and the
cut and fill still to go, overall and per zone; a period's progress is the change of those."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.types import GridSpec, SoilVolumeError
from ..inputs.crs import WorkFrame
from ..inputs.landxml import Tin
from ..inputs.surface import SurfaceSource, is_surface, on_grid, open_surface, read_over
from ..options import Options
from ..volumes.grade import grade


@dataclass(frozen=True)
class Design:
    """A series' design opened and checked, its on-grade tolerance (m) and its zones' file."""

    source: SurfaceSource | Tin
    tolerance: float
    zones: str | None


@dataclass(frozen=True)
class Graded:
    """Each epoch graded: the design on the grid (local heights), each epoch's classes and ``grade``."""

    design: str
    tolerance: float
    zones: str | None
    heights: np.ndarray
    classes: list[np.ndarray]
    grades: list[dict]


def open_design(options: Options) -> Design | None:
    """The series' design opened and checked (None without ``--design``, which ``--tolerance``,
    ``--zones`` and ``--design-surface`` need and which needs a tolerance); its zones grade the epochs only."""
    if options.design is None:
        for name in ("tolerance", "zones", "design_surface"):
            if getattr(options, name) is not None:
                raise SoilVolumeError(f"{{opt:{name}}}: a series takes it with {{opt:design}} (the design to grade on)")
        return None
    path = Path(options.design)
    if options.tolerance is None:
        raise SoilVolumeError(f"{{opt:design}} {path}: give {{opt:tolerance}} (the on-grade tolerance, m)")
    if not is_surface(path):
        raise SoilVolumeError(f"{{opt:design}} {path}: not a design surface (a .tif/.tiff GeoTIFF or a LandXML .xml)")
    if not path.is_file():
        raise SoilVolumeError(f"{{opt:design}} {path}: no such file")
    return Design(open_surface(path, options.before_crs, options.design_surface), options.tolerance, options.zones)


def design_heights(source: SurfaceSource | Tin, grid: GridSpec, frame: WorkFrame, valid: np.ndarray) -> np.ndarray:
    """The design's local heights at the cell centres; refused without any on the compared cells."""
    z = on_grid(read_over(source, *grid.box(), frame, 2 * grid.cell), grid) - grid.origin[2]
    if not (np.isfinite(z) & valid).any():
        raise SoilVolumeError(f"{source.path} does not overlap the series: no compared cell has a design height")
    return z


def grade_epochs(design: Design, epochs: list[np.ndarray], grid: GridSpec, frame: WorkFrame) -> Graded:
    """Each epoch's heights (local, on ``grid``) graded against the design."""
    valid = np.logical_or.reduce([np.isfinite(h) for h in epochs])
    z = design_heights(design.source, grid, frame, valid)
    done = [grade(h - z, grid, design.tolerance, design.zones) for h in epochs]
    classes, grades = [c for c, _ in done], [g for _, g in done]
    return Graded(str(design.source.path), design.tolerance, design.zones, z, classes, grades)
