"""The engine's public entry points: what the CLI, the QGIS algorithms and servers call.

Every function takes file paths and an :class:`~soilvolume.options.Options`, reports through the
optional ``progress(percent, message)``, ``log(message)`` and ``cancel() -> bool`` callbacks, and
raises :class:`~soilvolume.core.types.SoilVolumeError` (or :class:`Cancelled`) with a message naming
the file and the problem. Outputs are written atomically.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .core import interrupt
from .core.types import SoilVolumeError
from .options import Options
from .validate import check_bounds, check_options

Progress = Callable[[float, str], None]
Log = Callable[[str], None]
Cancel = Callable[[], bool]


class Cancelled(SoilVolumeError):
    """The user cancelled the run; nothing was written."""


@dataclass
class Hooks:
    """Progress, log and cancellation callbacks (all optional). A message is logged once even
    when a stage reports it many times (e.g. once per ICP level)."""

    progress: Progress | None = None
    log: Log | None = None
    cancel: Cancel | None = None
    _last: str | None = field(default=None, repr=False)

    def step(self, percent: float, message: str, log: bool = True) -> None:
        """Check for cancellation (:class:`Cancelled`, or ``Interrupted`` after SIGINT/SIGTERM),
        move the progress bar and log ``message`` (once)."""
        interrupt.check()
        if self.cancel is not None and self.cancel():
            raise Cancelled("cancelled by the user")
        if self.progress is not None:
            self.progress(percent, message)
        if log and message != self._last:
            self._last = message
            self.info(message)

    def info(self, message: str) -> None:
        if self.log is not None:
            self.log(message)

    def ticker(self, start: float, end: float, message: str, expected: int = 8) -> Callable[[], None]:
        """A ``check()`` callback for a long stage of unknown length (logged by the step that
        started it): each call checks for cancellation and moves the bar from ``start`` towards
        ``end`` (about 90 % of the way after ``expected`` calls, never reaching it)."""
        calls = [0]
        rate = 0.1 ** (1.0 / max(expected, 1))

        def check() -> None:
            calls[0] += 1
            self.step(start + (end - start) * (1.0 - rate ** calls[0]), message, log=False)

        return check


@dataclass
class Result:
    """The single source of a run's numbers: ``report`` is exactly what report.json holds,
    ``outputs`` maps output names (dem_before, dem_after, difference, plane_offset,
    after_registered, report_json, report_html, ...) to written paths."""

    report: dict[str, Any]
    outputs: dict[str, Path] = field(default_factory=dict)


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
    from .workflow.estimate import run_estimate

    return run_estimate(
        Path(before), Path(after), Path(out_dir), check_options(options or Options()), overwrite=overwrite,
        hooks=hooks or Hooks(), before_pipeline=before_pipeline, after_pipeline=after_pipeline,
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
    from .workflow.estimate import run_cloud_to_dem

    return run_cloud_to_dem(Path(cloud), Path(out_tif), check_options(options or Options()), crs=crs,
                            bounds=check_bounds(bounds),
                            hooks=hooks or Hooks())


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
    from .workflow.estimate import run_register

    return run_register(Path(before), Path(after), Path(out_cloud), check_options(options or Options()),
                        hooks=hooks or Hooks())


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
    from .workflow.rasters import run_volume_from_rasters

    return run_volume_from_rasters(Path(before_tif), Path(after_tif), Path(out_difference),
                                   zones=zones, zone_field=zone_field, hooks=hooks or Hooks())
