"""Volume between two DEM rasters a user already has (optionally per polygon zone)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import check_input_file, check_output_file, os_errors
from ..core.types import GridSpec, SoilVolumeError
from ..dem.grid import write_geotiff
from ..inputs.crs import parse_crs, xy_unit
from ..volumes.difference import budget

NO_CORRECTION = (
    "volume from the DEM difference as it is: no registration, no vertical bias correction and no "
    "uncertainty (for two point clouds, the estimate command does all three)"
)
FEET = {"ft", "foot", "feet", "us survey foot", "us-ft", "ftus", "us_survey_foot"}


def read_dem(path: Path) -> tuple[np.ndarray, Any]:
    """(heights in metres with NaN for nodata, the open profile) of a single-band DEM."""
    import rasterio

    check_input_file(path)
    try:
        with rasterio.open(path) as ds:
            band = ds.read(1, masked=True).astype("float64")
            unit = (ds.units[0] or "").strip().lower()
            profile = ds.profile
    except rasterio.errors.RasterioIOError as exc:
        raise SoilVolumeError(f"{path}: not a readable raster ({exc})") from exc
    if profile.get("crs") is None:
        raise SoilVolumeError(f"{path}: the raster has no CRS")
    z = band.filled(np.nan)
    if unit in FEET:
        z *= 0.3048006096 if "us" in unit else 0.3048
    return z, profile


def grid_of(profile: dict) -> GridSpec:
    """The engine's grid description of a north-up raster (square cells required)."""
    t = profile["transform"]
    if t.b != 0 or t.d != 0 or abs(abs(t.e) - t.a) > 1e-9 * t.a:
        raise SoilVolumeError("rasters must be north-up with square cells")
    crs = parse_crs(profile["crs"].to_wkt(), "raster")
    u = xy_unit(crs)
    return GridSpec(t.c * u, t.f * u, t.a * u, profile["height"], profile["width"], (0.0, 0.0, 0.0), crs.to_wkt(), u)


def resample_onto(z: np.ndarray, src: dict, dst: dict) -> np.ndarray:
    """``z`` (grid ``src``) resampled bilinearly onto the grid ``dst``."""
    from rasterio.warp import Resampling, reproject

    out = np.full((dst["height"], dst["width"]), np.nan)
    reproject(
        z,
        out,
        src_transform=src["transform"],
        src_crs=src["crs"],
        src_nodata=np.nan,
        dst_transform=dst["transform"],
        dst_crs=dst["crs"],
        dst_nodata=np.nan,
        resampling=Resampling.bilinear,
    )
    return out


def run_volume_from_rasters(
    before: Path, after: Path, out: Path, *, zones=None, zone_field=None, hooks: Hooks
) -> dict[str, Any]:
    """See :func:`soilvolume.api.volume_from_rasters`."""
    out = check_output_file(out, [before, after, zones])
    hooks.step(5, f"reading {before.name} and {after.name}")
    zb, pb = read_dem(before)
    za, pa = read_dem(after)
    same = (
        pa["transform"] == pb["transform"]
        and (pa["height"], pa["width"]) == (pb["height"], pb["width"])
        and pa["crs"] == pb["crs"]
    )
    if not same:
        hooks.info(f"resampling {after.name} onto the grid of {before.name}")
        za = resample_onto(za, pa, pb)
    grid = grid_of(pb)
    diff = za - zb
    if not np.isfinite(diff).any():
        raise SoilVolumeError(f"{before} and {after} do not overlap (no cell has both heights)")
    hooks.step(60, "computing cut and fill")
    hooks.info(NO_CORRECTION)
    median = float(np.nanmedian(diff))
    hooks.info(
        f"median difference over the whole grid: {median:+.3f} m ({np.isfinite(diff).sum():,} cells); "
        "a datum or georeferencing offset between the DEMs shows here and is counted as volume"
    )
    result: dict[str, Any] = {
        "total": _public(budget(diff, grid.cell_area)),
        "zones": [],
        "cell_m": grid.cell,
        "crs": parse_crs(grid.crs_wkt, "raster").name,
        "median_difference_m": median,
        "method": NO_CORRECTION,
    }
    if zones:  # before writing: a bad zones file leaves nothing behind
        from ..volumes.zones import zone_budgets

        result["zones"] = zone_budgets(diff, grid, zones, zone_field)
    hooks.step(90, f"writing {out.name}")
    with os_errors(out):
        write_geotiff(out, diff, grid, "after - before (m)")
    hooks.step(100, "done")
    return result


def _public(b: dict) -> dict:
    return {"net": b["net"], "cut": b["cut"], "fill": b["fill"], "area_m2": b["area_m2"], "cells": b["cells"]}
