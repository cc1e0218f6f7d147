"""Raster files written whole or not at all, also on a full disk.

GDAL ignores a write that fails while it closes a file (the last blocks, the directory): the
file is left truncated and no error reaches Python. So a raster is laid out by GDAL in memory
(``/vsimem/``) and its bytes are written by Python, whose writes raise on a full disk; a raster
too large for that is written by GDAL and checked afterwards (:func:`check_complete`).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..core.types import SoilVolumeError
from ..inputs.io import atomic_path

COPY_CHUNK = 1 << 22  # bytes per write when a raster staged in memory is saved


@contextmanager
def staged_raster(final: str | Path, **profile) -> Iterator:
    """A rasterio dataset opened for writing in memory; when the block succeeds its file is
    written to ``final`` atomically (:func:`save`)."""
    from rasterio.io import MemoryFile

    final = Path(final)
    with MemoryFile(ext=final.suffix) as mem:
        with mem.open(**profile) as dst:
            yield dst
        save(mem, final)


def staged_copy(final: str | Path, copy: Callable[[str], None]) -> None:
    """``copy(name)`` (GDAL writing a file at ``name``, e.g. ``rasterio.shutil.copy``) into memory,
    then the file written to ``final`` atomically (:func:`save`)."""
    from rasterio.io import MemoryFile

    final = Path(final)
    with MemoryFile(ext=final.suffix) as mem:
        copy(mem.name)
        save(mem, final)


def save(mem, final: Path) -> None:
    """The bytes of the in-memory file ``mem`` written to ``final`` by Python, atomically: a full
    disk raises an OSError naming ``final``, and nothing is left half-written."""
    mem.seek(0)
    try:
        with atomic_path(final) as tmp:
            with open(tmp, "wb") as fh:
                shutil.copyfileobj(mem, fh, COPY_CHUNK)
    except OSError as exc:
        exc.filename = str(final)  # not the hidden partial file
        raise


def check_complete(path: Path, final: Path) -> None:
    """Refuse a GeoTIFF GDAL wrote at ``path`` (for ``final``) that lacks its directory or whose
    blocks (of every band and overview) reach past the end of the file."""
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

    if ovr is None:
        (rows, cols), height, width = ds.block_shapes[band - 1], ds.height, ds.width
    else:
        with rasterio.open(path, overview_level=ovr) as level:
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
