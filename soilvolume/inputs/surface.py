"""A surface as the reference: a single-band DEM GeoTIFF (a grading plan, an earlier DEM) opened and
checked before any point is read, its heights read in metres over the survey's box only
(:mod:`heights`) and resampled onto a run's grid by GDAL's warp (bilinear, reprojected if need be);
or a LandXML TIN (:mod:`landxml`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj

from ..core.types import GridSpec, SoilVolumeError
from . import landxml
from .crs import WorkFrame, horizontal, raster_wkt, xy_unit
from .heights import HeightRaster, Heights, metres_per_unit, open_heights, read_heights, window_over

SUFFIXES = (".tif", ".tiff", *landxml.SUFFIXES)  # a first input with one of these is a surface, not a cloud


def is_surface(path: str | Path | None) -> bool:
    """Whether an estimate's first input is a surface (a GeoTIFF or a LandXML TIN), not a point cloud."""
    return path is not None and Path(path).suffix.lower() in SUFFIXES


@dataclass(frozen=True)
class SurfaceSource:
    """A reference surface opened and checked: its CRS and heights' unit; no height read yet."""

    raster: HeightRaster
    crs: pyproj.CRS  # the raster's CRS (or --before-crs), possibly with a vertical part
    factor: float  # metres per stored height unit (after the band's scale and offset)
    vertical_unit: str  # where the heights' unit came from, in words

    @property
    def path(self) -> str:
        return self.raster.path


@dataclass(frozen=True)
class Surface:
    """A reference surface (``source``) and its heights in metres (NaN where it has none) over the
    window of its raster that covers the survey (``got``)."""

    source: SurfaceSource
    got: Heights

    @property
    def path(self) -> str:
        return self.source.path

    @property
    def masked(self) -> tuple[dict, ...]:
        """Values taken as nodata though not declared (:attr:`heights.Heights.masked`)."""
        return tuple(self.got.masked)

    def describe(self) -> dict:
        """report.json's description of the reference: the whole raster, the window read, its valid cells."""
        raster, crs, t = self.source.raster, self.source.crs, self.got.transform
        return {
            "kind": "surface",
            "path": self.path,
            "crs": crs.name,
            "crs_wkt": crs.to_wkt(),
            "rows": raster.height,
            "cols": raster.width,
            "window": dict(zip(("col_off", "row_off", "cols", "rows"), self.got.window, strict=True)),
            "resolution_m": float(np.hypot(t.a, t.d)) * xy_unit(crs),  # CRS units times their metres
            "valid_cells": int(np.isfinite(self.got.z).sum()),
            "vertical_unit": self.source.vertical_unit,
            **raster.describe(),
            "masked_as_nodata": list(self.masked),
        }


def open_surface(path: Path, crs_override: str | None, name: str | None = None) -> SurfaceSource | landxml.Tin:
    """Open and check a reference DEM (one band, a CRS: :func:`landxml.surface_crs`, heights' unit), or
    read a LandXML file's TIN surface (``name``, else its first) whole."""
    if landxml.is_landxml(path):
        return landxml.open_tin(path, crs_override, name)
    raster = open_heights(path)
    words = ("the raster's", "a raster")
    crs = landxml.surface_crs(path, raster.crs, crs_override, "the raster has no CRS", words, vertical=True)
    factor, where = metres_per_unit(crs, raster.unit, str(path))
    return SurfaceSource(raster, crs, factor, where)


def read_over(
    source: SurfaceSource | landxml.Tin, lo: np.ndarray, hi: np.ndarray, frame: WorkFrame, margin_m: float
) -> Surface | landxml.Tin:
    """The surface's heights over the box lo..hi (absolute, metres) plus ``margin_m`` and two pixels
    for the resampling's kernel (a TIN: itself, when it meets the box)."""
    if isinstance(source, landxml.Tin):
        return landxml.check_over(source, lo, hi, frame, margin_m)
    lo = (np.asarray(lo[:2], float) - margin_m) / frame.xy_unit
    hi = (np.asarray(hi[:2], float) + margin_m) / frame.xy_unit
    window = window_over(source.raster, source.crs, lo, hi, frame.crs, pad=2)
    if window is None:
        raise SoilVolumeError(
            f"{source.path} does not overlap the survey: its extent misses the survey's (check the CRSs)"
        )
    got = read_heights(source.raster, source.factor, window)
    if not np.isfinite(got.z).any():
        raise SoilVolumeError(f"{source.path} does not overlap the survey: every cell of it over the survey is nodata")
    return Surface(source, got)


def on_grid(surface: Surface | landxml.Tin, grid: GridSpec, method: str = "bilinear") -> np.ndarray:
    """The surface's heights (m) at the cell centres of ``grid`` (NaN where none) by GDAL's warp; a TIN
    linear inside its own triangles whatever ``method``."""
    if isinstance(surface, landxml.Tin):
        return landxml.on_grid(surface, grid)
    from rasterio.crs import CRS
    from rasterio.warp import Resampling, reproject

    out = np.full((grid.rows, grid.cols), np.nan)
    reproject(
        surface.got.z,
        out,
        src_transform=surface.got.transform,
        src_crs=CRS.from_wkt(horizontal(surface.source.crs).to_2d().to_wkt()),
        src_nodata=np.nan,
        dst_transform=grid.transform,
        dst_crs=CRS.from_wkt(raster_wkt(grid.crs_wkt)),
        dst_nodata=np.nan,
        resampling=getattr(Resampling, method),
    )
    return out


def valid_box(surface: Surface | landxml.Tin, frame_crs: pyproj.CRS, xy_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box (absolute x/y in the frame, metres) of the surface's valid cells."""
    if isinstance(surface, landxml.Tin):
        return landxml.box(surface, frame_crs, xy_unit)
    rows, cols = np.nonzero(np.isfinite(surface.got.z))
    r = np.array([rows.min(), rows.min(), rows.max() + 1, rows.max() + 1], float)
    c = np.array([cols.min(), cols.max() + 1, cols.min(), cols.max() + 1], float)
    t = surface.got.transform
    x, y = t.a * c + t.b * r + t.c, t.d * c + t.e * r + t.f
    src, dst = horizontal(surface.source.crs), horizontal(frame_crs)
    if not src.equals(dst):
        x, y = pyproj.Transformer.from_crs(src, dst, always_xy=True).transform(x, y, errcheck=False)
        x, y = np.asarray(x, float), np.asarray(y, float)
    xy = np.c_[x, y] * xy_unit
    if not np.isfinite(xy).all():
        raise SoilVolumeError(f"{surface.path}: its extent cannot be transformed into {dst.name}")
    return xy.min(axis=0), xy.max(axis=0)
