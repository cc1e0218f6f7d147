"""A streamed chunk's work on the native kernel (``sv_chunk``): decode into the working frame, crop,
split soil from the rest, thin and keep the points within the box as float32, in one pass. Its
numpy twin, :func:`numpy_chunk` (the path without the library), gives the same bits."""

from __future__ import annotations

import ctypes
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ..core.cells import in_box, rows
from ..core.types import SoilVolumeError
from ..native import OFF_THE_GIL, ChunkArgs, address
from ..soil.points import SOIL
from .records import PIECE, FileChunk, Records, decoded_xyz
from .thinning import ColumnThinner

NOTHING = (np.full(2, np.inf), np.full(2, -np.inf))  # the x/y bounds of no point


class Growing:
    """Rows appended into one buffer sized up front (pages never written are never resident), doubled
    past it; :meth:`room` hands a kernel the free tail to write into."""

    def __init__(self, capacity: int, width: int | None = 3, dtype=np.float32) -> None:
        self.shape = (width,) if width else ()
        self.buf = np.empty((max(capacity, 0), *self.shape), dtype)
        self.n = 0

    def room(self, m: int) -> np.ndarray:
        """The buffer's free tail, at least ``m`` rows (grown when needed)."""
        if self.n + m > len(self.buf):
            grown = np.empty((max(2 * len(self.buf), self.n + m), *self.shape), self.buf.dtype)
            grown[: self.n] = self.buf[: self.n]
            self.buf = grown
        return self.buf[self.n :]

    def append(self, rows_: np.ndarray) -> None:
        self.room(len(rows_))[: len(rows_)] = rows_
        self.n += len(rows_)

    def result(self) -> np.ndarray:
        return self.buf[: self.n]


@dataclass
class Counted:
    """One chunk's soil points within the footprint, soil points, and absolute per-axis bounds."""

    cropped: int
    soil: int
    lo: np.ndarray
    hi: np.ndarray


class NativeChunks:
    """One epoch's chunks on ``sv_chunk`` with its crop ``polygon`` (``PolygonMask`` or None),
    ``thinner``, full-resolution x/y ``box`` (None: all) and ``origin``; :meth:`add` passes a piece
    (``chunk``: the most points of a chunk, whose column sums are added up after its last piece)."""

    def __init__(self, lib: ctypes.CDLL, thinner: ColumnThinner, polygon, box, origin: np.ndarray, chunk: int) -> None:
        self.lib, self.thinner = lib, thinner
        a = self.args = ChunkArgs()
        a.origin[:] = [float(v) for v in origin]
        self.framed = None
        if polygon is not None:
            self.framed = np.ascontiguousarray(polygon.framed, np.uint8)
            a.framed = address(self.framed)
            a.plo[:], a.pres = [float(v) for v in polygon.lo], float(polygon.res)
            a.prows, a.pcols = polygon.mask.shape
        a.tlo[:], a.voxel = [float(v) for v in thinner.lo], thinner.voxel
        a.first[:], a.shape[:] = [int(v) for v in thinner.first], [int(v) for v in thinner.shape]
        self.state = thinner.native_state(chunk)
        a.ncols, a.sums = thinner.sums.shape[1], address(thinner.sums)
        a.mark, a.side_ids, a.side = (address(x) for x in self.state)
        a.chunk, a.nside = 1, 0
        a.use_box = int(box is not None)
        if box is not None:
            a.box[:] = [float(box[0][0]), float(box[0][1]), float(box[1][0]), float(box[1][1])]
        self.holds = box is None or bool((np.asarray(box[1]) >= np.asarray(box[0])).all())  # a box points can be in
        self.files: dict[str, int] = {}
        self.buf: np.ndarray | None = None
        self.span = NOTHING  # x/y bounds of the pieces since the last flush

    def add(self, rec, labels: np.ndarray | None, parts: Growing, others: Growing, other_labels: Growing):
        """A piece (:class:`Records` and ``labels``) or a :class:`FileChunk`: kept soil points appended
        to ``parts``, the others within the crop and box to ``others`` with their labels."""
        a, n = self.args, len(rec)
        file = isinstance(rec, FileChunk)
        array = None if file else np.ascontiguousarray(rec.array)
        dtype = rec.dtype if file else array.dtype
        a.rec, a.n, a.stride = address(array), n, dtype.itemsize
        a.field[:] = [dtype.fields[k][1] for k in "XYZ"]
        a.scale[:], a.offset[:] = [float(v) for v in rec.scales], [float(v) for v in rec.offsets]
        lab = None if labels is None else np.ascontiguousarray(labels, np.uint8)
        a.labels, a.flush = address(lab), int(rec.flush)
        room, others_room = (n, n if (rec.table if file else lab) is not None else 0) if self.holds else (0, 0)
        a.out = address(parts.room(room))
        a.others, a.other_labels = address(others.room(others_room)), address(other_labels.room(others_room))
        if file:
            self._from_file(rec)
        else:
            self.lib.sv_chunk(ctypes.byref(a))
        parts.n += a.kept
        others.n += a.other
        other_labels.n += a.other
        return Counted(a.cropped, a.soil, np.array(a.lo[:]), np.array(a.hi[:]))

    def _from_file(self, rec: FileChunk) -> None:
        """``sv_file_chunk``: the chunk read and worked on in the kernel (each file opened once)."""
        if rec.path not in self.files:
            self.files[rec.path] = os.open(rec.path, os.O_RDONLY)
        if self.buf is None:
            self.buf = np.empty(PIECE * rec.dtype.itemsize, np.uint8)
        buf, room = address(self.buf), len(self.buf) // rec.dtype.itemsize
        table = None if rec.table is None else np.ascontiguousarray(rec.table, np.uint8)  # alive through the call
        where = (self.files[rec.path], rec.offset, rec.count)
        OFF_THE_GIL.set()
        try:
            failed = self.lib.sv_file_chunk(
                ctypes.byref(self.args), *where, buf, room, address(table), rec.cls_at, rec.cls_mask
            )
        finally:
            OFF_THE_GIL.clear()
        if failed:
            raise SoilVolumeError(f"{rec.path}: corrupt LAS file (its points end before the header's count)")

    def close(self) -> None:
        """Close the files :meth:`add` opened."""
        for fd in self.files.values():
            os.close(fd)
        self.files.clear()


def numpy_chunk(
    rec: Records,
    labels: np.ndarray | None,
    origin: np.ndarray,
    polygon,
    thinner: ColumnThinner,
    box,
    parts: Growing,
    others: Growing,
    other_labels: Growing,
) -> Counted:
    """:meth:`NativeChunks.add` in numpy: the twin the tests hold the kernel to."""
    local, lo, hi = decoded_xyz(rec, origin)
    soil = None if labels is None else labels == 0
    inside = None if polygon is None else polygon(local)
    return Counted(*keep_chunk(local, soil, inside, labels, thinner, box, parts, others, other_labels), lo, hi)


def keep_chunk(local, soil, inside, labels, thinner, box, parts, others, other_labels) -> tuple[int, int]:
    """(points cropped in, soil points) of ``local`` points kept by numpy (masks None: all)."""
    n_soil = len(local) if soil is None else int(soil.sum())
    if soil is not None:  # the points that are not soil, within the crop and the box
        other = ~soil if inside is None else ~soil & inside
        o_xyz, o_lab = rows(local, other), labels[other]
        if box is not None:
            near = in_box(o_xyz, *box)
            o_xyz, o_lab = rows(o_xyz, near), o_lab[near]
        others.append(o_xyz)
        other_labels.append(o_lab)
    mask = soil if inside is None else (inside if soil is None else soil & inside)
    if mask is not None:  # one compress for soil and crop
        local = rows(local, mask)
    thinner.add(local)
    cropped = len(local)
    if box is not None:
        local = rows(local, in_box(local, *box))
    parts.append(local)
    return cropped, n_soil


def consume(chunks: Iterator[tuple], work: Callable, index: list | None, check) -> tuple:
    """Every chunk through ``work`` ((cropped, soil, x/y box of a whole chunk or None)), the boxes into
    ``index``; returns (points, soil points, cropped, seconds waiting for chunks, the rule)."""
    points = used = cropped = start = 0
    reading, rule, t0 = 0.0, None, time.perf_counter()
    for item in chunks:
        reading += time.perf_counter() - t0
        if check:
            check()
        rule = item[2]
        n_crop, n_soil, xy_box = work(item)
        if index is not None and xy_box is not None:  # a chunk's box (native: once its last piece passed)
            index.append((start, points + len(item[0]) - start, *xy_box))
        points += len(item[0])
        start = start if xy_box is None else points
        used += n_soil
        cropped += n_crop
        t0 = time.perf_counter()
    return points, used, cropped, reading + time.perf_counter() - t0, rule


def native_work(kernel: NativeChunks, item: tuple, out: tuple) -> tuple:
    """One piece through the native kernel; the x/y box of the pieces since the last flush at a flush."""
    local, labels = item[:2]
    got = kernel.add(local, labels, *out)
    local.check.extend(got.lo, got.hi)
    if local.last:
        local.check.finish()
    piece = np.minimum(kernel.span[0], got.lo[:2]), np.maximum(kernel.span[1], got.hi[:2])
    kernel.span, box = (NOTHING, piece) if local.flush else (piece, None)
    return got.cropped, got.soil, box


def numpy_work(shift, keep, thinner: ColumnThinner, box, item: tuple, out: tuple) -> tuple:
    """One chunk through numpy (the reading thread may have tested ``keep`` already)."""
    local, labels, _, xy_box, inside = item
    local = shift(local)
    if inside is None and keep is not None:  # not tested by the reading thread
        inside = keep(local)
    soil = None if labels is None else labels == SOIL
    return (*keep_chunk(local, soil, inside, labels, thinner, box, *out), xy_box)
