"""The engine's public entry points: what the CLI, the QGIS algorithms and servers call.

Every function takes file paths and an :class:`~soilvolume.options.Options` (checked first,
:func:`~soilvolume.validate.check_options`), reports through the optional ``progress(percent,
message)``, ``log(message)`` and ``cancel() -> bool`` callbacks of its :class:`Hooks`, and raises
:class:`~soilvolume.core.types.SoilVolumeError` (or :class:`Cancelled`) with a message naming the
file and the problem. Outputs are written atomically.
"""

from .core.hooks import Cancelled, Hooks, Result
from .workflow.commands import run_cloud_to_dem as cloud_to_dem
from .workflow.commands import run_register as register
from .workflow.estimate import run_estimate as estimate
from .workflow.rasters import run_volume_from_rasters as volume_from_rasters
from .workflow.series import run_series as series

__all__ = ["Cancelled", "Hooks", "Result", "cloud_to_dem", "estimate", "register", "series", "volume_from_rasters"]
