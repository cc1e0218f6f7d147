"""The engine's public entry points: what the CLI, the QGIS algorithms and servers call.

Every function takes file paths and an :class:`~soilvolume.options.Options`, reports through the
optional ``progress(percent, message)``, ``log(message)`` and ``cancel() -> bool`` callbacks, and
raises :class:`~soilvolume.core.types.SoilVolumeError` (or :class:`Cancelled`) with a message naming
the file and the problem. Outputs are written atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .core.hooks import Cancelled, Hooks, Result
from .options import Options
from .validate import check_bounds, check_options
from .workflow.commands import run_cloud_to_dem, run_register
from .workflow.estimate import run_estimate
from .workflow.rasters import run_volume_from_rasters
from .workflow.series import run_series

__all__ = ["Cancelled", "Hooks", "Result", "cloud_to_dem", "estimate", "register", "series", "volume_from_rasters"]


def estimate(
    before: str | Path,
    after: str | Path,
    out_dir: str | Path,
    options: Options | None = None,
    *,
    overwrite: bool = False,
    hooks: Hooks | None = None,
    before_pipeline: str | Path | None = None,
    after_pipeline: str | Path | None = None,
) -> Result:
    """The whole method: read, crop, register, compensate, grid, difference, volumes, report."""
    options = check_options(options or Options())
    return run_estimate(
        Path(before),
        Path(after),
        Path(out_dir),
        options,
        overwrite=overwrite,
        hooks=hooks or Hooks(),
        before_pipeline=before_pipeline,
        after_pipeline=after_pipeline,
    )


def cloud_to_dem(
    cloud: str | Path,
    out_tif: str | Path,
    options: Options | None = None,
    *,
    crs: str | None = None,
    bounds: tuple[float, float, float, float] | None = None,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """One cloud to an average-height GeoTIFF (``options.cell``/``options.statistic``; ``bounds``
    = xmin, ymin, xmax, ymax in the cloud's CRS, snapped outwards to the cell). Returns the grid
    description (cell_m, rows, cols, crs, transform, points, valid_cells)."""
    return run_cloud_to_dem(
        Path(cloud),
        Path(out_tif),
        check_options(options or Options()),
        crs=crs,
        bounds=check_bounds(bounds),
        hooks=hooks or Hooks(),
    )


def register(
    before: str | Path,
    after: str | Path,
    out_cloud: str | Path,
    options: Options | None = None,
    *,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """Register the after cloud onto the before cloud and write it (LAS/LAZ, before CRS).
    Returns {"transform": 4x4 row-major list (after in before CRS -> before), "coarse": {...},
    "fine": {...}}."""
    return run_register(
        Path(before), Path(after), Path(out_cloud), check_options(options or Options()), hooks=hooks or Hooks()
    )


def volume_from_rasters(
    before_tif: str | Path,
    after_tif: str | Path,
    out_difference: str | Path,
    *,
    zones: str | Path | None = None,
    zone_field: str | None = None,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """Cut/fill/net between two DEMs a user already has (the after raster is resampled onto the
    before grid when they differ). Returns {"total": {"net","cut","fill","area_m2"}, "zones":
    [{"id", "name", "net", "cut", "fill", "area_m2"}, ...]} and writes the difference GeoTIFF."""
    return run_volume_from_rasters(
        Path(before_tif),
        Path(after_tif),
        Path(out_difference),
        zones=zones,
        zone_field=zone_field,
        hooks=hooks or Hooks(),
    )


def series(
    epochs: list[str | Path],
    out_dir: str | Path,
    options: Options | None = None,
    *,
    dates: list[str] | None = None,
    overwrite: bool = False,
    hooks: Hooks | None = None,
) -> Result:
    """Volume change over a series of surveys, E0 (``epochs[0]``) the reference: report.json
    holds ``epochs`` (each registration into E0's frame), ``periods`` (one per consecutive pair)
    and ``cumulative``; the periods' nets add up to the cumulative net. ``dates``: one per epoch
    (YYYY-MM-DD; empty keeps the file's)."""
    return run_series(
        [Path(e) for e in epochs],
        Path(out_dir),
        check_options(options or Options()),
        dates=dates,
        overwrite=overwrite,
        hooks=hooks or Hooks(),
    )
