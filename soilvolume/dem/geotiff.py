"""Every GeoTIFF the engine writes, whole or not at all, also on a full disk: a :class:`Layout`
and three writers, :func:`write_geotiff` (bands in memory), :func:`write_cog` (filled window by
window) and :func:`write_grid` (a run's raster on its grid). GDAL ignores a write failing while it
closes a file (left truncated, no error): so GDAL lays a raster out in memory and Python writes its
bytes (raising on a full disk); one too large for that is checked after GDAL (:func:`check_complete`)."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.types import GridSpec, SoilVolumeError
from ..inputs.crs import raster_wkt
from ..inputs.io import atomic_path

NODATA = -9999.0  # of a run's float rasters; its uint8 ones: 255
COPY_CHUNK = 1 << 22  # bytes per write when a raster staged in memory is saved
BLOCK = 256  # a COG's tile side
IN_MEMORY_CELLS = 1 << 24  # up to this many cells a COG is staged in memory (64 MB of float32), not on disk
PROFILE = ("driver", "width", "height", "count", "dtype", "crs", "transform", "nodata")  # a Layout's, for rasterio


@dataclass(frozen=True)
class Layout:
    """What a GeoTIFF holds besides its values: ``options`` GDAL's creation options, ``tags`` the
    dataset's, ``descriptions``/``units`` one per band or none."""

    width: int
    height: int
    transform: object  # an affine.Affine
    crs: str | None
    dtype: str = "float32"
    nodata: float | None = None
    count: int = 1
    descriptions: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    tags: tuple[tuple[str, str], ...] = ()
    options: tuple[tuple[str, object], ...] = ()
    driver: str = "GTiff"

    def profile(self) -> dict:
        """rasterio's keyword arguments for a file of this layout."""
        return {**{key: getattr(self, key) for key in PROFILE}, **dict(self.options)}

    def filled(self, values: np.ndarray) -> np.ndarray:
        """``values`` in the layout's data type, NaN and infinities as nodata."""
        if self.nodata is None:
            return np.asarray(values).astype(self.dtype)
        return np.where(np.isfinite(values), values, self.nodata).astype(self.dtype)


def grid_layout(grid: GridSpec, description: str = "", units: str = "metre", dtype: str = "float32") -> Layout:
    """A run's single-band raster on ``grid``: its horizontal CRS only (the values are metres
    whatever the input's vertical unit), :data:`NODATA` (255 for integers), DEFLATE, cell areas."""
    nodata = NODATA if np.dtype(dtype).kind == "f" else 255
    options = (("compress", "deflate"), ("tiled", grid.cols >= BLOCK and grid.rows >= BLOCK))
    look = dict(descriptions=(description,), units=(units,), tags=(("AREA_OR_POINT", "Area"),), options=options)
    return Layout(grid.cols, grid.rows, grid.transform, raster_wkt(grid.crs_wkt), dtype, nodata, **look)


def write_grid(
    path: str | Path,
    array: np.ndarray,
    grid: GridSpec,
    description: str = "",
    units: str = "metre",
    dtype: str = "float32",
) -> Path:
    """A run's single-band raster (NaN -> nodata) on ``grid`` (:func:`grid_layout`); returns the path."""
    return write_geotiff(path, [array], grid_layout(grid, description, units, dtype))


def write_geotiff(path: str | Path, bands: Sequence[np.ndarray], layout: Layout) -> Path:
    """``bands`` (NaN -> nodata) as a GeoTIFF of ``layout``, laid out in memory and written
    atomically (a full disk raises an OSError naming ``path``); returns the path."""
    from rasterio.io import MemoryFile

    path = Path(path)
    with MemoryFile(ext=path.suffix) as mem:
        with mem.open(**layout.profile()) as dst:
            for band, values in enumerate(bands, start=1):
                dst.write(layout.filled(values), band)
            _describe(dst, layout)
        _save(mem, path)
    return path


def _describe(dst, layout: Layout) -> None:
    """The bands' descriptions and units and the dataset's tags set on the open ``dst``."""
    for band, text in enumerate(layout.descriptions, start=1):
        dst.set_band_description(band, text)
    for band, unit in enumerate(layout.units, start=1):
        dst.set_band_unit(band, unit)
    if layout.tags:
        dst.update_tags(**dict(layout.tags))


def _save(mem, final: Path) -> None:
    """The in-memory file ``mem`` written to ``final`` atomically (a full disk: an OSError naming it)."""
    mem.seek(0)
    try:
        with atomic_path(final) as tmp, open(tmp, "wb") as fh:
            shutil.copyfileobj(mem, fh, COPY_CHUNK)
    except OSError as exc:
        exc.filename = str(final)  # not the hidden partial file
        raise


def write_cog(path: str | Path, layout: Layout, piece: Callable[[slice, slice], np.ndarray]) -> Path:
    """A single-band COG of ``layout`` (DEFLATE, :data:`BLOCK` tiles, overviews), its values
    ``piece(rows, cols)`` filled block row by block row, staged in memory (GDAL's MEM driver, the
    COG through memory) up to :data:`IN_MEMORY_CELLS` cells, else on disk and checked complete."""
    import rasterio
    from rasterio.io import MemoryFile

    path = Path(path)
    tiles = (("compress", "deflate"), ("tiled", True), ("blockxsize", BLOCK), ("blockysize", BLOCK))
    layout = replace(layout, options=(*tiles, ("BIGTIFF", "IF_SAFER")))
    if layout.width * layout.height <= IN_MEMORY_CELLS:
        with rasterio.open("", "w", driver="MEM", **{key: getattr(layout, key) for key in PROFILE[1:]}) as dst:
            _fill(dst, layout, piece)
            with MemoryFile(ext=path.suffix) as mem:
                _cog_copy(dst, mem.name, layout.dtype)
                _save(mem, path)
        return path
    plain = path.with_name(f".{path.stem}.blocks.tif")
    try:
        with rasterio.open(plain, "w", **layout.profile()) as dst:
            _fill(dst, layout, piece)
        check_complete(plain, path)  # the blocks file GDAL wrote and closed
        with atomic_path(path) as tmp:
            _cog_copy(plain, tmp, layout.dtype)
            check_complete(tmp, path)
    finally:
        plain.unlink(missing_ok=True)
    return path


def _fill(dst, layout: Layout, piece: Callable[[slice, slice], np.ndarray]) -> None:
    """``dst``'s band filled by windows of one block row and eight blocks, and described."""
    from rasterio.windows import Window

    for r0 in range(0, layout.height, BLOCK):
        rows = slice(r0, min(r0 + BLOCK, layout.height))
        for c0 in range(0, layout.width, 8 * BLOCK):
            cols = slice(c0, min(c0 + 8 * BLOCK, layout.width))
            data = layout.filled(piece(rows, cols))
            dst.write(data, 1, window=Window(cols.start, rows.start, data.shape[1], data.shape[0]))
    _describe(dst, layout)


def _cog_copy(src, name, dtype: str) -> None:
    """``src`` (a dataset or a file) copied by GDAL as a COG to ``name``."""
    import rasterio.shutil

    resampling = "nearest" if dtype == "uint8" else "average"
    rasterio.shutil.copy(src, name, driver="COG", compress="DEFLATE", blocksize=BLOCK, overview_resampling=resampling)


def check_complete(path: Path, final: Path) -> None:
    """Refuse a GeoTIFF at ``path`` (for ``final``) without its directory or with blocks (of any band
    or overview) past its end."""
    import rasterio

    size = path.stat().st_size
    try:
        with rasterio.open(path) as ds:
            levels = [None, *range(len(ds.overviews(1)))]
            end = max(_block_end(ds, path, band, ovr) for band in ds.indexes for ovr in levels)
    except rasterio.errors.RasterioError:
        end = size + 1  # no readable directory: cut off before it
    if end > size:
        raise SoilVolumeError(f"{final}: cannot write (the file was cut off at {size:,} bytes: is the disk full?)")


def _block_end(ds, path: Path, band: int, ovr: int | None) -> int:
    """Where the last byte of a band's (or its overview's) blocks lies in the file."""
    import rasterio

    with rasterio.open(path, overview_level=ovr) as level:  # None: the full resolution
        (rows, cols), height, width = level.block_shapes[band - 1], level.height, level.width
    end = 0
    for y in range(-(-height // rows)):
        for x in range(-(-width // cols)):
            offset = ds.get_tag_item(f"BLOCK_OFFSET_{x}_{y}", "TIFF", bidx=band, ovr=ovr)
            length = ds.get_tag_item(f"BLOCK_SIZE_{x}_{y}", "TIFF", bidx=band, ovr=ovr)
            if offset is None or length is None:
                return 1 << 62  # a block the directory does not place
            end = max(end, int(offset) + int(length))
    return end
