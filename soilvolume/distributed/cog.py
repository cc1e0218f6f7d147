"""Cloud-Optimized GeoTIFFs written window by window: a tiled, DEFLATE-compressed GeoTIFF filled
one block row at a time, then laid out as a COG (internal overviews) by GDAL's COG driver."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from ..dem.grid import NODATA, UINT8_LAYERS, output_layers
from ..dem.rasterfile import check_complete, staged_copy
from ..inputs.io import atomic_path

BLOCK = 256
IN_MEMORY_CELLS = 1 << 24  # up to this many cells a raster is staged in memory (64 MB of float32), not on disk


def write_cog(
    path: str | Path,
    grid: GridSpec,
    piece: Callable[[slice, slice], np.ndarray],
    description: str = "",
    units: str = "metre",
    dtype: str = "float32",
) -> Path:
    """Write ``piece(rows, cols)`` (the raster's values on that window; NaN = nodata) block row by
    block row as a single-band COG, atomically; returns the path. Tagged as every output raster
    (:func:`inputs.crs.raster_wkt`, also dem/grid.write_geotiff's)."""
    from rasterio.windows import Window

    from ..inputs.crs import raster_wkt

    path = Path(path)
    nodata = NODATA if np.dtype(dtype).kind == "f" else 255
    profile = dict(
        driver="GTiff",
        width=grid.cols,
        height=grid.rows,
        count=1,
        dtype=dtype,
        crs=raster_wkt(grid.crs_wkt),  # as dem/grid.write_geotiff: horizontal only, the values are metres
        transform=grid.transform,
        nodata=nodata,
        compress="deflate",
        tiled=True,
        blockxsize=BLOCK,
        blockysize=BLOCK,
        BIGTIFF="IF_SAFER",
    )
    small = grid.rows * grid.cols <= IN_MEMORY_CELLS
    plain = path.with_name(f".{path.stem}.blocks.tif")
    try:
        with _staged(plain, profile, small) as dst:
            for r0 in range(0, grid.rows, BLOCK):
                rows = slice(r0, min(r0 + BLOCK, grid.rows))
                for c0 in range(0, grid.cols, 8 * BLOCK):
                    cols = slice(c0, min(c0 + 8 * BLOCK, grid.cols))
                    data = piece(rows, cols)
                    data = np.where(np.isfinite(data), data, nodata).astype(dtype)
                    dst.write(data, 1, window=Window(cols.start, rows.start, data.shape[1], data.shape[0]))
            dst.set_band_description(1, description)
            dst.set_band_unit(1, units)
            dst.update_tags(AREA_OR_POINT="Area")
            if small:
                _as_cog(dst, path, dtype)
        if not small:
            _as_cog(plain, path, dtype)
    finally:
        plain.unlink(missing_ok=True)
    return path


def _staged(plain: Path, profile: dict, small: bool):
    """Where the raster's blocks are written before the COG is laid out from them: GDAL's MEM
    driver for a small raster, else a tiled GeoTIFF on disk at ``plain`` (memory stays bounded)."""
    import rasterio

    if small:
        keep = ("width", "height", "count", "dtype", "crs", "transform", "nodata")
        return rasterio.open("", "w", driver="MEM", **{k: profile[k] for k in keep})
    return rasterio.open(plain, "w", **profile)


def _as_cog(src, path: Path, dtype: str) -> None:
    """``src`` (a dataset or a file) laid out as a COG at ``path``, whole or not at all: a dataset
    in memory (a small raster) through memory, its bytes written by Python; a file's COG written
    by GDAL, then checked complete (GDAL ignores a full disk while it closes a file)."""
    import rasterio.shutil

    def copy(name) -> None:
        resampling = "nearest" if dtype == "uint8" else "average"
        rasterio.shutil.copy(
            src, name, driver="COG", compress="DEFLATE", blocksize=BLOCK, overview_resampling=resampling
        )

    if not isinstance(src, (str, Path)):
        staged_copy(path, copy)
        return
    check_complete(Path(src), path)  # the blocks file GDAL wrote and closed
    with atomic_path(path) as tmp:
        copy(tmp)
        check_complete(tmp, path)


def write_outputs(out, get: Callable[[str, slice, slice], np.ndarray], grid: GridSpec, z0: float, correction: str):
    """The rasters of a run (:func:`grid.output_layers`) as COGs, block by block;
    ``get(name, rows, cols)`` gives the window of the grid array ``name`` (heights local)."""
    for name, key, desc in output_layers(correction):
        if key in UINT8_LAYERS:
            write_cog(out.path(name), grid, lambda r, c, key=key: get(key, r, c).astype("uint8"), desc, "", "uint8")
        else:
            add = z0 if key.startswith("dem_") else 0.0
            write_cog(out.path(name), grid, lambda r, c, key=key, add=add: get(key, r, c) + add, desc)
