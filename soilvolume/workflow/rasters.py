"""Volume between two DEMs a user already has (optionally per zone): each read in metres
(:mod:`soilvolume.inputs.heights`), the after's over the before's extent, resampled when the grids differ."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import check_output_file, os_errors
from ..core.types import GridSpec, SoilVolumeError
from ..dem.geotiff import write_grid
from ..inputs.crs import horizontal, parse_crs, xy_unit
from ..inputs.heights import (
    Heights,
    masked_notes,
    metres_per_unit,
    open_heights,
    read_heights,
    window_over,
)
from ..inputs.io import check_two_surveys
from ..inputs.surface import SurfaceSource as Dem
from ..volumes.change import budget
from ..volumes.zones import zone_budgets

NO_CORRECTION = (
    "volume from the DEM difference as it is: no registration, no vertical bias correction and no "
    "uncertainty (for two point clouds, the estimate command does all three)"
)


def open_dem(path: Path) -> Dem:
    """A DEM opened, its CRS (required) and heights' unit checked; no pixel read."""
    raster = open_heights(path)
    if raster.crs is None:
        raise SoilVolumeError(f"{path}: the raster has no CRS")
    return Dem(raster, raster.crs, *metres_per_unit(raster.crs, raster.unit, str(path)))


def after_on_before(after: Dem, before: Dem, hb: Heights) -> tuple[np.ndarray, Heights]:
    """The after DEM's heights on the grid of the before's ``hb``: read over the before's extent only
    (two of its cells around), resampled bilinearly by GDAL's warp (horizontal CRSs)."""
    from rasterio.crs import CRS
    from rasterio.warp import Resampling, reproject

    t, (h, w), pad = hb.transform, hb.z.shape, 2.0
    xs, ys = zip(*(t @ (c, r) for c in (-pad, w + pad) for r in (-pad, h + pad)), strict=True)
    window = window_over(
        after.raster, after.crs, np.array([min(xs), min(ys)]), np.array([max(xs), max(ys)]), before.crs
    )
    if window is None:
        raise SoilVolumeError(f"{before.raster.path} and {after.raster.path} do not overlap")
    got = read_heights(after.raster, after.factor, window)
    out = np.full((h, w), np.nan)
    reproject(
        got.z,
        out,
        src_transform=got.transform,
        src_crs=CRS.from_wkt(horizontal(after.crs).to_2d().to_wkt()),
        src_nodata=np.nan,
        dst_transform=t,
        dst_crs=CRS.from_wkt(horizontal(before.crs).to_2d().to_wkt()),
        dst_nodata=np.nan,
        resampling=Resampling.bilinear,
    )
    return out, got


def grid_of(dem: Dem, heights: Heights) -> GridSpec:
    """The engine's grid description of ``heights`` (a north-up window of ``dem``: square cells required)."""
    t = heights.transform
    if t.b != 0 or t.d != 0 or abs(abs(t.e) - t.a) > 1e-9 * t.a:
        raise SoilVolumeError("rasters must be north-up with square cells")
    crs = parse_crs(dem.crs.to_wkt(), "raster")
    u, (rows, cols) = xy_unit(crs), heights.z.shape
    return GridSpec(t.c * u, t.f * u, t.a * u, rows, cols, (0.0, 0.0, 0.0), crs.to_wkt(), u)


def run_volume_from_rasters(
    before: str | Path,
    after: str | Path,
    out: str | Path,
    *,
    zones: str | Path | None = None,
    zone_field: str | None = None,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """Cut/fill/net between two DEMs (``api.volume_from_rasters``), the after resampled onto the before's grid:
    {"total": {"net", "cut", "fill", "area_m2", "cells"}, "zones": [...], ...}; writes the difference GeoTIFF."""
    before, after, hooks = Path(before), Path(after), hooks or Hooks()
    check_two_surveys(before, after, "the before DEM")
    out = check_output_file(Path(out), [before, after, zones])
    hooks.step(5, f"reading {before.name} and {after.name}")
    db, da = open_dem(before), open_dem(after)
    hb, ha, za = read_both(db, da, hooks)
    grid, diff = grid_of(db, hb), za - hb.z
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
        "total": {
            k: v for k, v in budget(diff, grid.cell_area).items() if k in ("net", "cut", "fill", "area_m2", "cells")
        },
        "zones": [],
        "cell_m": grid.cell,
        "crs": parse_crs(grid.crs_wkt, "raster").name,
        "median_difference_m": median,
        "method": NO_CORRECTION,
        "inputs": {  # each DEM and what of it was read
            key: {"path": d.path, "vertical_unit": d.vertical_unit, **d.raster.describe(), "masked_as_nodata": h.masked}
            for key, d, h in (("before", db, hb), ("after", da, ha))
        },
    }
    if zones:  # before writing: a bad zones file leaves nothing behind
        result["zones"] = zone_budgets(diff, grid, zones, zone_field)
    hooks.step(90, f"writing {out.name}")
    with os_errors(out):
        write_grid(out, diff, grid, "after - before (m)")
    hooks.step(100, "done")
    return result


def read_both(db: Dem, da: Dem, hooks: Hooks) -> tuple[Heights, Heights, np.ndarray]:
    """(the whole before DEM: the difference's grid, the after DEM read, its heights on that grid:
    resampled when the grids differ), their masked values said."""
    hb = read_heights(db.raster, db.factor)
    rb, ra = db.raster, da.raster
    if (ra.transform, ra.width, ra.height) == (rb.transform, rb.width, rb.height) and da.crs.equals(db.crs):
        ha = read_heights(ra, da.factor)
        za = ha.z
    else:
        hooks.info(f"resampling {Path(ra.path).name} onto the grid of {Path(rb.path).name}")
        za, ha = after_on_before(da, db, hb)
    for note in masked_notes(rb.path, hb.masked) + masked_notes(ra.path, ha.masked):
        hooks.info(note)
    return hb, ha, za
