"""A surface as the reference: a single-band DEM GeoTIFF (a grading plan, or an earlier DEM)
read and checked, and resampled onto a run's grid (GDAL's warp through rasterio: bilinear at
the cell centres, reprojected when the raster's CRS is not the grid's)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from ..core.outputs import check_input_file
from ..core.types import GridSpec, SoilVolumeError
from .crs import has_vertical, horizontal, parse_crs, raster_wkt, z_unit

SUFFIXES = (".tif", ".tiff")  # a first input with one of these is a surface, not a point cloud
FEET = {"ft": 0.3048, "foot": 0.3048, "feet": 0.3048, "us survey foot": 0.3048006096, "us-ft": 0.3048006096}
FEET |= {"ftus": 0.3048006096, "us_survey_foot": 0.3048006096}
METRES = {"", "m", "metre", "meter", "metres", "meters"}


def is_surface(path: str | Path | None) -> bool:
    """Whether an estimate's first input is a surface (a GeoTIFF) rather than a point cloud."""
    return path is not None and Path(path).suffix.lower() in SUFFIXES


@dataclass(frozen=True)
class Surface:
    """A reference surface: heights in metres (NaN where it has none) on its own raster grid."""

    path: str
    heights: np.ndarray  # (rows, cols) float64, metres
    transform: Any  # affine.Affine of the raster, in its CRS's units
    crs: pyproj.CRS  # the raster's CRS (or --before-crs), possibly with a vertical part
    vertical_unit: str  # where the heights' unit came from, in words

    @property
    def resolution_m(self) -> float:
        """The raster's pixel size (m; CRS units times their metres)."""
        from .crs import xy_unit

        return float(np.hypot(self.transform.a, self.transform.d)) * xy_unit(self.crs)

    def describe(self) -> dict:
        """report.json's description of the reference (``inputs.before`` and ``reference``)."""
        rows, cols = self.heights.shape
        return {
            "kind": "surface",
            "path": self.path,
            "crs": self.crs.name,
            "crs_wkt": self.crs.to_wkt(),
            "rows": rows,
            "cols": cols,
            "resolution_m": self.resolution_m,
            "valid_cells": int(np.isfinite(self.heights).sum()),
            "vertical_unit": self.vertical_unit,
        }


def read_surface(path: Path, crs_override: str | None) -> Surface:
    """Read and check a reference DEM: one band, a CRS (its own, or ``--before-crs`` for a raster
    without one; a contradicting one is refused), heights in metres (the vertical CRS's unit, or
    the band's declared unit)."""
    import rasterio

    check_input_file(path)
    try:
        with rasterio.open(path) as ds:
            if ds.count != 1:
                raise SoilVolumeError(
                    f"{path}: the reference surface must be a single-band DEM; this raster has {ds.count} bands"
                )
            band = ds.read(1, masked=True).astype("float64").filled(np.nan)
            unit, transform, header = (ds.units[0] or "").strip().lower(), ds.transform, ds.crs
    except rasterio.errors.RasterioIOError as exc:
        raise SoilVolumeError(f"{path}: not a readable raster ({' '.join(str(exc).split())[:200]})") from exc
    crs = _crs(path, header, crs_override)
    factor, where = _vertical(crs, unit, path)
    heights = band * factor
    if not np.isfinite(heights).any():
        raise SoilVolumeError(f"{path}: the raster has no valid height (every cell is nodata)")
    return Surface(str(path), heights, transform, crs, where)


def _crs(path: Path, header, override: str | None) -> pyproj.CRS:
    given = parse_crs(override, "{opt:before_crs}")
    own = None if header is None else pyproj.CRS.from_user_input(header.to_wkt())
    if own is None and given is None:
        raise SoilVolumeError(f"{path}: the raster has no CRS; give {{opt:before_crs}} (e.g. EPSG:32654)")
    if own is not None and given is not None and not horizontal(own).equals(horizontal(given), ignore_axis_order=True):
        raise SoilVolumeError(
            f"{path}: {{opt:before_crs={override}}} differs from the raster's CRS ({own.name}); "
            "{opt:before_crs} applies only to a raster without one"
        )
    if given is not None and (own is None or has_vertical(given)):
        return given
    return own


def _vertical(crs: pyproj.CRS, unit: str, path: Path) -> tuple[float, str]:
    """(metres per height unit, where that came from): a vertical CRS's axis, else the band's unit."""
    if crs.is_compound or len(crs.axis_info) == 3:
        return z_unit(crs), f"the vertical CRS ({z_unit(crs):g} m per unit)"
    if unit in FEET:
        return FEET[unit], f"the band's unit ({unit})"
    if unit in METRES:
        return 1.0, "metres" if not unit else f"the band's unit ({unit})"
    raise SoilVolumeError(f"{path}: heights in '{unit}' are not understood (expected metres or feet)")


def on_grid(surface: Surface, grid: GridSpec, method: str = "bilinear") -> np.ndarray:
    """The surface's absolute heights (m) at the cell centres of ``grid`` (NaN where it has none):
    GDAL's warp, reprojecting the raster's horizontal CRS onto the grid's."""
    from rasterio.crs import CRS
    from rasterio.warp import Resampling, reproject

    out = np.full((grid.rows, grid.cols), np.nan)
    reproject(
        surface.heights,
        out,
        src_transform=surface.transform,
        src_crs=CRS.from_wkt(horizontal(surface.crs).to_2d().to_wkt()),
        src_nodata=np.nan,
        dst_transform=grid.transform,
        dst_crs=CRS.from_wkt(raster_wkt(grid.crs_wkt)),
        dst_nodata=np.nan,
        resampling=getattr(Resampling, method),
    )
    return out


def valid_box(surface: Surface, frame_crs: pyproj.CRS, xy_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box (absolute x/y in the frame, metres) of the surface's valid cells."""
    rows, cols = np.nonzero(np.isfinite(surface.heights))
    r = np.array([rows.min(), rows.min(), rows.max() + 1, rows.max() + 1], float)
    c = np.array([cols.min(), cols.max() + 1, cols.min(), cols.max() + 1], float)
    t = surface.transform
    x, y = t.a * c + t.b * r + t.c, t.d * c + t.e * r + t.f
    src, dst = horizontal(surface.crs), horizontal(frame_crs)
    if not src.equals(dst):
        x, y = pyproj.Transformer.from_crs(src, dst, always_xy=True).transform(x, y, errcheck=False)
        x, y = np.asarray(x, float), np.asarray(y, float)
    xy = np.c_[x, y] * xy_unit
    if not np.isfinite(xy).all():
        raise SoilVolumeError(f"{surface.path}: its extent cannot be transformed into {dst.name}")
    return xy.min(axis=0), xy.max(axis=0)
