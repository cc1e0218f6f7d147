"""A LAS/LAZ file's raw point records, chunk by chunk, for the native kernels, which decode them in
the same pass as the rest of a chunk's work. Uncompressed files are read into three buffers in turn
(on a virtual machine a page fault costs microseconds, and laspy's reader faults a new buffer per
chunk), so a consumer may hold one while the next fills; LAZ chunks are what lazrs decompresses."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from itertools import takewhile
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError, short_error
from ..soil.points import Signals
from .lasheader import BoundsCheck

PIECE = 125_000  # points read at a time (a chunk of 1 M points in 8 pieces: 3.75 MB buffers of 30-byte records)
RING = 3  # buffers of an uncompressed read in turn: the consumer's, the queued one, the one being read


@dataclass
class Records:
    """One undecoded piece of a chunk (laspy's point format), the header's scales and offsets, the
    file's bounds check (the consumer extends it, and finishes it on the file's ``last`` piece)."""

    array: np.ndarray
    scales: np.ndarray
    offsets: np.ndarray
    check: BoundsCheck
    last: bool
    flush: bool = True  # the last piece of a chunk of ``size`` points (the numpy path's chunk)

    def __len__(self) -> int:
        return len(self.array)


@dataclass
class FileChunk:
    """A whole chunk of an uncompressed LAS file left for the native kernel to read (``sv_file_chunk``),
    labelled by ``table`` (by LAS class: the byte at ``cls_at`` masked by ``cls_mask``; None: soil)."""

    path: str
    offset: int  # of its first record in the file
    count: int
    dtype: np.dtype
    cls_at: int
    cls_mask: int
    table: np.ndarray | None
    scales: np.ndarray | None = None  # of the header; these four set by las_records
    offsets: np.ndarray | None = None
    check: BoundsCheck | None = None
    last: bool = False
    flush: bool = True

    def __len__(self) -> int:
        return self.count


def class_byte(dtype: np.dtype) -> tuple[int, int] | None:
    """(byte offset, mask) of the classification in a point record (formats 0-5: the low 5 bits of
    ``raw_classification``; 6-10: its own byte), None without one."""
    fields = dtype.fields or {}
    if "classification" in fields and fields["classification"][0] == np.uint8:
        return fields["classification"][1], 0xFF
    if "raw_classification" in fields:
        return fields["raw_classification"][1], 0x1F
    return None


def las_records(
    path: Path,
    count: int,
    size: int,
    signals: bool | Callable = False,
    piece: int | None = None,
    ring: int = RING,
    direct: Callable[[bool], object] | None = None,
    stop: int | None = None,
    whole_first: bool = False,
    mapped: bool = False,
) -> Iterator[tuple]:
    """(Records, classification or None, signals or None) in pieces of at most ``piece`` points, chunks of
    ``size`` ending on ``flush``; not ``count`` points: corrupt. ``ring`` buffers, or ``mapped`` (all in one
    view); ``stop``: the first points only; ``whole_first``: the first chunk in one piece; ``direct(has_class)`` giving
    a class table (or None) leaves an uncompressed chunk in the file (:class:`FileChunk`)."""
    import laspy

    read = 0
    try:
        with laspy.open(path) as reader:
            h = reader.header
            dims = set(h.point_format.dimension_names)
            scales, offsets = np.asarray(h.scales, float), np.asarray(h.offsets, float)
            check = BoundsCheck(path, h)
            chunks = chunk_pieces(count if stop is None else stop, size, PIECE if piece is None else piece)
            if whole_first and chunks:
                chunks[0] = [sum(chunks[0])]
            if h.are_points_compressed:
                # up to the first empty read: fewer points than the header says, reported below
                arrays = takewhile(len, (reader.read_points(m).array for c in chunks for m in c))
            else:
                arrays = _mapped(path, h, sum(map(sum, chunks))) if mapped else _raw(path, h, chunks, ring, direct)
            for array in arrays:
                read += len(array)
                if isinstance(array, FileChunk):
                    array.scales, array.offsets, array.check, array.last = scales, offsets, check, read >= count
                    yield array, None, None
                    continue
                rec = laspy.ScaleAwarePointRecord(array, h.point_format, scales, offsets)
                cls = np.array(rec.classification) if "classification" in dims else None
                sig = point_signals(rec, signal_dims(dims, signals, cls)) if signals else None
                yield Records(array, scales, offsets, check, read >= count, read % size == 0 or read >= count), cls, sig
                del rec, array
    except SoilVolumeError:
        raise
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc
    if read != (count if stop is None else stop):
        raise SoilVolumeError(f"{path}: corrupt LAS file (header says {count} points, read {read})")


def first_chunk_signals(path: Path, count: int, size: int, signals: bool | Callable) -> tuple:
    """(classification, signals) of a LAS/LAZ file's first chunk, coordinates not decoded: what the
    epoch's rule is decided on, the same points the numpy path decides it on."""
    for _rec, cls, sig in las_records(path, count, size, signals, piece=size, stop=min(size, count), mapped=True):
        return cls, sig  # the chunk in one piece, as the numpy path reads it
    return None, None


def las_chunks(
    path: Path, count: int, size: int, signals: bool | Callable = False, origin: np.ndarray | None = None
) -> Iterator[tuple]:
    """(absolute xyz float64, classification or None[, signals: :func:`signal_dims`]) of a LAS/LAZ
    file, ``size`` points at a time (one read buffer); with ``origin``, ``xyz - origin``."""
    for rec, cls, sig in las_records(path, count, size, signals, piece=size, ring=1):
        xyz, lo, hi = decoded_xyz(rec, origin)
        rec.check.extend(lo, hi)
        if rec.last:
            rec.check.finish()
        item = (xyz, cls, sig) if signals else (xyz, cls)
        del rec, xyz, cls, sig  # the record is not held while the consumer works (or the queue is full)
        yield item


def signal_dims(dims: set[str], signals, cls: np.ndarray | None) -> set[str]:
    """The dimensions of ``dims`` read for a chunk of classes ``cls``: all, or those ``signals(cls)`` names."""
    return dims if signals is True else dims & set(signals(cls))


BLOCK = 1 << 14  # points decoded at a time: a block's column stays in the cache through its passes


def decoded_xyz(chunk, origin: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xyz, lo, hi) of a point record: ``X * scale + offset`` as laspy computes it (minus ``origin``)
    and its per-axis bounds, block by block through a small scratch column (one pass over memory)."""
    n = len(chunk)
    xyz = np.empty((n, 3))
    if n == 0:
        return xyz, np.full(3, np.inf), np.full(3, -np.inf)
    ints = [chunk.array[name] for name in "XYZ"]
    scratch = np.empty(min(n, BLOCK))
    lows, highs = np.empty((3, -(-n // BLOCK))), np.empty((3, -(-n // BLOCK)))
    with np.errstate(over="ignore", invalid="ignore"):  # checked against the bounds by the caller
        for b, start in enumerate(range(0, n, BLOCK)):
            stop = min(n, start + BLOCK)
            t = scratch[: stop - start]
            for k in range(3):
                np.multiply(ints[k][start:stop], chunk.scales[k], out=t)
                np.add(t, chunk.offsets[k], out=t)
                lows[k, b], highs[k, b] = t.min(), t.max()
                if origin is None:
                    xyz[start:stop, k] = t
                else:
                    np.subtract(t, origin[k], out=xyz[start:stop, k])
    return xyz, lows.min(axis=1), highs.max(axis=1)


def decoded_points(pts, dims: set[str], signals, origin=None) -> tuple:
    """(xyz float64 minus ``origin``, classification or None[, signals: :func:`signal_dims`]) of
    laspy points decoded by laspy."""
    xyz = np.empty((len(pts), 3))
    xyz[:, 0], xyz[:, 1], xyz[:, 2] = pts.x, pts.y, pts.z
    if origin is not None:
        np.subtract(xyz, origin, out=xyz)
    cls = np.array(pts.classification) if "classification" in dims else None
    return (xyz, cls, point_signals(pts, signal_dims(dims, signals, cls))) if signals else (xyz, cls)


def point_signals(record, dims: set[str]) -> Signals | None:
    """The colour and return numbers of a laspy point record (None when it has neither)."""
    rgb = ret = None
    if {"red", "green", "blue"} <= dims:
        rgb = np.column_stack([np.asarray(record.red), np.asarray(record.green), np.asarray(record.blue)])
    if {"return_number", "number_of_returns"} <= dims:
        ret = np.column_stack([np.asarray(record.return_number), np.asarray(record.number_of_returns)]).astype(np.uint8)
    return None if rgb is None and ret is None else Signals(rgb, ret)


def chunk_pieces(count: int, size: int, piece: int) -> list[list[int]]:
    """Per chunk of ``size`` of ``count`` points, its pieces' lengths (at most ``piece``)."""
    return [
        [min(piece, m - k) for k in range(0, m, piece)] for m in (min(size, count - s) for s in range(0, count, size))
    ]


def _mapped(path: Path, header, m: int) -> Iterator[np.ndarray]:
    """The first ``m`` points of an uncompressed file (fewer when it is short) as one read-only mapped
    view: the page cache's pages, not a buffer faulted in (for one look at the first chunk's classes
    and signals)."""
    dtype = header.point_format.dtype()
    base = header.offset_to_point_data
    n = min(m, max(0, (path.stat().st_size - base) // dtype.itemsize))
    if n > 0:
        yield np.memmap(path, dtype, mode="r", offset=base, shape=(n,)).view(np.ndarray)


def _raw(path: Path, header, chunks: list[list[int]], ring: int, direct=None) -> Iterator:
    """An uncompressed file's pieces read into ``ring`` buffers in turn, or a chunk left in the file
    where ``direct`` says (:func:`las_records`)."""
    dtype = header.point_format.dtype()
    stride, cls, base = dtype.itemsize, class_byte(dtype), header.offset_to_point_data
    room = max((m for chunk in chunks for m in chunk), default=0) * stride
    buffers: list[np.ndarray] = []
    at = read = 0
    with open(path, "rb") as fh:
        for chunk in chunks:
            table = direct(cls is not None) if direct is not None else False
            if table is not False:
                yield FileChunk(str(path), base + at * stride, sum(chunk), dtype, *(cls or (0, 0)), table)
                at += sum(chunk)
                continue
            fh.seek(base + at * stride)
            for m in chunk:
                if len(buffers) < ring:
                    buffers.append(np.empty(room, np.uint8))  # pages faulted when read
                view = buffers[read % len(buffers)][: m * stride]
                read += 1
                got = fh.readinto(view) or 0
                yield np.frombuffer(view, dtype=dtype, count=got // stride)
                if got != m * stride:
                    return
                at += m
