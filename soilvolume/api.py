"""The engine's public entry points (the CLI's, QGIS's, servers'): each takes file paths and an
:class:`~soilvolume.options.Options` (checked first), reports through its optional :class:`Hooks` and
raises :class:`~soilvolume.core.types.SoilVolumeError` (or :class:`Cancelled`) naming the file and the
problem; outputs are written atomically."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable

from .core.hooks import Cancelled, Hooks, Result
from .options import Options
from .validate import check_options
from .workflow.commands import run_cloud_to_dem, run_register
from .workflow.estimate import run_estimate
from .workflow.rasters import run_volume_from_rasters as volume_from_rasters
from .workflow.series import run_series

__all__ = ["Cancelled", "Hooks", "Result", "cloud_to_dem", "estimate", "register", "series", "volume_from_rasters"]


def checked(run: Callable) -> Callable:
    """``run`` (same signature and docstring) with its ``options`` (default: the defaults) checked first."""
    signature = inspect.signature(run)

    @functools.wraps(run)
    def call(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.arguments["options"] = check_options(bound.arguments.get("options") or Options())
        return run(*bound.args, **bound.kwargs)

    return call


estimate, series = checked(run_estimate), checked(run_series)
cloud_to_dem, register = checked(run_cloud_to_dem), checked(run_register)
