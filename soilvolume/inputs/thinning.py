"""Voxel thinning while streaming: the centroid of each column of a fixed grid, chunk by chunk."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import native
from ..core.types import SoilVolumeError

#: most columns a thinning grid may have (4 float64 sums each: 2 GB)
MAX_COLUMNS = 1 << 26


def narrowed(thinning: tuple, box: tuple) -> tuple:
    """A thinner's (lo, hi, voxel[, within]) with ``within`` narrowed to ``box``, where all points to
    come lie: the same lattice, over the columns meeting it (one VPC tile's, not the epoch's)."""
    lo, hi, voxel, within = (*thinning, None)[:4]
    if within is not None:
        box = (np.maximum(box[0][:2], within[0][:2]), np.minimum(box[1][:2], within[1][:2]))
    return lo, hi, voxel, box


@dataclass(frozen=True)
class Block:
    """A narrowed thinner's first column (x, y), shape (rows, columns) and sums (4, rows * columns), to
    add to the wider one (:meth:`ColumnThinner.add_block`)."""

    first: tuple[int, int]
    shape: tuple[int, int]
    sums: np.ndarray


class ColumnThinner:
    """The centroid of the points in each ``voxel`` column of a fixed box, chunk by chunk; with ``within``
    (an x/y box holding all points) only the columns meeting it, on the same lattice. ``name``: errors'."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, voxel: float, within=None, name: str = "") -> None:
        self.lo, self.hi, self.voxel = np.asarray(lo[:2], float), np.asarray(hi[:2], float), float(voxel)
        self.within = within
        first = np.zeros(2, np.int64)
        last = np.ceil((self.hi - self.lo) / voxel).astype(np.int64)
        if within is not None:
            first = np.maximum(first, np.floor((np.asarray(within[0][:2]) - self.lo) / voxel).astype(np.int64) - 1)
            last = np.minimum(last, np.ceil((np.asarray(within[1][:2]) - self.lo) / voxel).astype(np.int64) + 1)
        self.first = first
        self.shape = (int(max(last[1] - first[1], -1)) + 1, int(max(last[0] - first[0], -1)) + 1)
        n = self.shape[0] * self.shape[1]
        if n > MAX_COLUMNS:
            raise SoilVolumeError(
                f"{name + ': ' if name else ''}{self.shape[0]:,} x {self.shape[1]:,} columns of {voxel:.3g} m to "
                "thin: the extent is far larger than the points (corrupt header bounds, or {opt:radius} too large)"
            )
        self.sums = np.zeros((4, n))
        self._native: tuple | None = None
        self._added = False  # by :meth:`add`: one thinner is fed by numpy or by the kernel, never both

    def occupied(self) -> tuple[np.ndarray, np.ndarray]:
        """(ids of the columns with points, their sums): what a scan of a tile hands back."""
        has = np.flatnonzero(self.sums[3])
        return has, self.sums[:, has]

    def block(self) -> Block:
        """This thinner's sums as a :class:`Block` of its lattice."""
        return Block((int(self.first[0]), int(self.first[1])), self.shape, self.sums)

    def add_block(self, block: Block) -> None:
        """Add the sums of ``block`` (over columns of this lattice) where it has points, in place."""
        h, w = block.shape
        if h * w == 0:
            return
        dx, dy = block.first[0] - int(self.first[0]), block.first[1] - int(self.first[1])
        if dx < 0 or dy < 0 or dy + h > self.shape[0] or dx + w > self.shape[1]:
            raise ValueError("the block lies outside the thinner's columns")
        view = self.sums.reshape(4, *self.shape)[:, dy : dy + h, dx : dx + w]
        part = block.sums.reshape(4, h, w)
        np.add(view, part, out=view, where=part[3] > 0)

    def native_state(self, chunk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The native kernel's state beside the sums, made once: the chunk that last touched each column,
        and room for the sums of ``chunk`` columns (the most points between two flushes)."""
        if self._native is None:
            if self._added:  # the kernel writes a column's first point over its sums: they must be zero
                raise RuntimeError("a thinner fed by numpy cannot go on with the native kernel")
            n = self.sums.shape[1]
            room = min(n, chunk)
            self._native = (np.zeros(n, np.int32), np.empty(room, np.int64), np.empty((room, 4)))
        return self._native

    def add(self, xyz: np.ndarray) -> None:
        """Add a chunk's points, over the span of columns it meets only (not the whole sums)."""
        if self._native is not None:  # columns it left at zero would be written over by the kernel
            raise RuntimeError("a thinner fed by the native kernel cannot go on with numpy")
        self._added = True
        ix, iy = self._index(xyz[:, 0], 0), self._index(xyz[:, 1], 1)
        # as unsigned, a negative index is past the end: one comparison per axis tests both bounds
        ok = np.less(ix.view(np.uint64), self.shape[1]) & np.less(iy.view(np.uint64), self.shape[0])
        every = bool(ok.all())
        iy *= self.shape[1]
        iy += ix
        ids = iy if every else np.compress(ok, iy)
        if not len(ids):
            return
        first = int(ids.min())
        ids -= first
        span = int(ids.max()) + 1
        sums = self.sums[:, first : first + span]
        sums[3] += np.bincount(ids, minlength=span)
        for k in range(3):
            sums[k] += np.bincount(ids, weights=xyz[:, k] if every else np.compress(ok, xyz[:, k]), minlength=span)

    def _index(self, v: np.ndarray, axis: int) -> np.ndarray:
        """``int((v - lo) / voxel) - first`` along ``axis`` (int64), with one temporary."""
        t = np.subtract(v, self.lo[axis])
        t /= self.voxel
        out = t.astype(np.int64)
        out -= self.first[axis]
        return out

    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(centroids float64 (M, 3), points behind each) in one pass (``sv_centroids``)."""
        lib = native.kernels()
        if lib is not None and self.sums.flags.c_contiguous:
            m = int(np.count_nonzero(self.sums[3] > 0))
            out, counts = np.empty((m, 3)), np.empty(m, np.int64)
            lib.sv_centroids(self.sums.ctypes.data, self.sums.shape[1], out.ctypes.data, counts.ctypes.data)
            return out, counts
        filled = np.flatnonzero(self.sums[3] > 0)
        count = self.sums[3].take(filled)
        out = np.empty((len(filled), 3))
        for k in range(3):  # column by column: no (3, M) temporaries and transposed copy
            np.divide(self.sums[k].take(filled), count, out=out[:, k])
        return out, count.astype(np.int64)
