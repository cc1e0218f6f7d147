"""A seeded pair's before ground as a reference surface: the analytic terrain of the before epoch
written as a single-band DEM GeoTIFF (what a design or an earlier DEM is to ``soilvolume
estimate DESIGN.tif AFTER.laz``); the truth of the pair is then the truth against the surface."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .config import SceneConfig
from .world import _World


def write_surface(
    path: str | Path,
    seed: int,
    config: SceneConfig,
    *,
    cell: float = 0.5,
    offset_m: float = 0.0,
    crs: str | None = "",
    bands: int = 1,
    unit: str = "metre",
    shift_xy: tuple[float, float] = (0.0, 0.0),
) -> Path:
    """Write the before epoch's ground of ``(seed, config)`` over the before survey's box as a
    GeoTIFF of ``cell`` pixels, heights at the pixel centres plus ``offset_m`` (a datum error);
    ``crs``: "" the scene's, None none; ``bands`` > 1 repeats the band (a bad input);
    ``unit``: the band's declared unit (heights are converted to it); ``shift_xy``: the raster
    placed that far off (m, e.g. away from the survey)."""
    import rasterio
    from affine import Affine

    world = _World(seed, config)
    (w, h), o = config.before_size, config.origin
    cols, rows = int(np.ceil(w / cell)), int(np.ceil(h / cell))
    x = (np.arange(cols) + 0.5) * cell
    y = h - (np.arange(rows) + 0.5) * cell
    xx, yy = np.meshgrid(x, y)
    z = world.terrain(xx.ravel(), yy.ravel()).reshape(rows, cols) + o[2] + offset_m
    z = z / 0.3048 if unit in ("ft", "foot", "feet") else z
    transform = Affine(cell, 0.0, o[0] + shift_xy[0], 0.0, -cell, o[1] + shift_xy[1] + h)
    profile = dict(driver="GTiff", width=cols, height=rows, count=bands, dtype="float32", transform=transform)
    profile.update(nodata=float("nan"), crs=config.crs if crs == "" else crs)
    path = Path(path)
    with rasterio.open(path, "w", **profile) as dst:
        for b in range(1, bands + 1):
            dst.write(z.astype("float32"), b)
            dst.set_band_unit(b, unit)
    return path
