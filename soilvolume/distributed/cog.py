"""A tiled run's rasters as Cloud-Optimized GeoTIFFs, block by block (:func:`dem.geotiff.write_cog`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..core.types import GridSpec
from ..dem.geotiff import grid_layout, write_cog
from ..dem.grid import UINT8_LAYERS, output_layers


def write_outputs(out, get: Callable[[str, slice, slice], np.ndarray], grid: GridSpec, z0: float, correction: str):
    """The rasters of a run (:func:`grid.output_layers`) as COGs, block by block;
    ``get(name, rows, cols)`` gives the window of the grid array ``name`` (heights local)."""
    for name, key, desc in output_layers(correction):
        if key in UINT8_LAYERS:
            layout = grid_layout(grid, desc, "", "uint8")
            write_cog(out.path(name), layout, lambda r, c, key=key: get(key, r, c).astype("uint8"))
        else:
            add = z0 if key.startswith("dem_") else 0.0
            write_cog(out.path(name), grid_layout(grid, desc), lambda r, c, key=key, add=add: get(key, r, c) + add)
