"""Per-cell statistics of heights already assigned to cells: counts, the cell statistic (mean,
median or robust mean), spreads and skews, through one sort of (cell, height) keys."""

from __future__ import annotations

import math
import threading

import numpy as np

from .. import native
from ..core.types import SoilVolumeError

QUANTUM = 1e-4  # m: heights are sorted as whole multiples of it (0.1 mm)
BLOCK = 4_000_000  # points per block of the key and running-sum loops (32 MB temporaries)
K_MAD = 3.0  # robust-mean: the heights within this many robust standard deviations of the cell's median
SPLIT_SORT = 2_000_000  # fewest keys sorted as two halves on two threads (when the caller's arrays are ours)


def cell_heights(
    ids: np.ndarray,
    z: np.ndarray,
    shape: tuple[int, int],
    statistic: str = "robust-mean",
    full: bool = False,
    own: bool = False,
) -> tuple[np.ndarray, ...]:
    """Per-cell height (NaN where empty) and count of heights ``z`` in flat cells ``ids`` of a ``shape``
    grid (a tile gets the whole grid's cells); ``robust-mean``: the mean within :data:`K_MAD` robust
    standard deviations (from the IQR, floor 1 cm) of the cell's median. With ``full`` also the robust
    spread (IQR / 1.349; the standard deviation for ``mean``) and each cell's height minus its median
    (0 for median, NaN where empty). ``own``: ``ids`` and ``z`` may be overwritten."""
    if statistic not in ("mean", "median", "robust-mean"):
        raise SoilVolumeError(f"unknown cell statistic '{statistic}'")
    n = shape[0] * shape[1]
    median = statistic == "median" and len(z) > 0
    if statistic == "mean" or len(z) == 0:
        counts = np.bincount(ids, minlength=n)
        h = _mean(ids, z, counts, n)
        if not full:
            return h.reshape(shape), counts.reshape(shape)
        sigma = np.sqrt(np.maximum(_mean(ids, z * z, counts, n) - h * h, 0.0))
        med = _SortedCells(ids, z, n, own).quantile(0.5) if len(z) else h
    else:
        keys = _SortedCells(ids, z, n, own)
        counts, med = keys.counts, keys.quantile(0.5)
        sigma = (keys.quantile(0.75) - keys.quantile(0.25)) / 1.349
        bound = K_MAD * np.maximum(sigma, 0.01)
        h = med if median else keys.mean_between(med - bound, med + bound)
    out = (h.reshape(shape), counts.reshape(shape))
    return out + ((sigma.reshape(shape), np.zeros(shape) if median else (h - med).reshape(shape)) if full else ())


class _SortedCells:
    """Heights sorted by (cell, height) through one sort of int64 keys ``cell << bits | level``,
    a level ``rint(z / q)`` less ``base``: any subset of the points (a tile, the whole grid)
    quantises a height alike (from each call's lowest point, a tiled DEM differed by up to 1.4 cm).
    ``own``: the keys are built in ``ids`` and ``z`` (no arrays faulted in anew), from
    :data:`SPLIT_SORT` keys on sorted as two halves on two threads."""

    def __init__(self, ids: np.ndarray, z: np.ndarray, n_cells: int, own: bool = False) -> None:
        low = float(z.min())
        self.bits = 62 - max(1, int(n_cells).bit_length())
        self.q = max(QUANTUM, (float(z.max()) - low) / (2**self.bits - 4))
        self.base = math.floor(low / self.q)  # every level rint(z / q) - base is >= 0 and fits the bits
        lib = native.kernels()
        ids = ids.astype(np.int64, copy=False)
        self.counts = np.zeros(n_cells, np.int64)
        if lib is not None and z.dtype == np.float64 and ids.flags.c_contiguous and z.flags.c_contiguous and len(z):
            self.key = self._native(lib, ids, z, n_cells, own)
        else:
            self.key = self._numpy(ids, z, n_cells, own)
        self.starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]])
        self.has = self.counts > 0

    def _numpy(self, ids: np.ndarray, z: np.ndarray, n_cells: int, own: bool) -> np.ndarray:
        """The keys built, counted and sorted in numpy."""
        key = np.left_shift(ids, self.bits, out=ids if own else None)
        t = np.divide(z, self.q, out=z if own and z.dtype == np.float64 else None)  # rounded in place
        np.rint(t, out=t)
        t -= self.base  # whole numbers: exact
        for i in range(0, len(key), BLOCK):
            key[i : i + BLOCK] |= t[i : i + BLOCK].astype(np.int64)
            self.counts += np.bincount(key[i : i + BLOCK] >> self.bits, minlength=n_cells)
        del t
        if own and len(key) >= SPLIT_SORT and _spare(z, key):
            return _sorted_halves(key, z.view(np.int64), self.counts, self.bits)
        key.sort(kind="stable")  # the same keys in order; timsort runs on file order (~2.5x faster)
        return key

    def _native(self, lib, ids: np.ndarray, z: np.ndarray, n_cells: int, own: bool) -> np.ndarray:
        """The same on the native kernels (``sv_keys``, ``sv_sort_keys``), into ``ids`` and ``z`` when ``own``."""
        key = ids if own else np.empty_like(ids)
        counts = self.counts.ctypes.data
        lib.sv_keys(ids.ctypes.data, z.ctypes.data, len(z), self.base, self.q, self.bits, key.ctypes.data, counts)
        out = z.view(np.int64) if own and _spare(z, key) else np.empty_like(key)
        pos = np.empty(n_cells, np.int64)
        lib.sv_sort_keys(key.ctypes.data, len(key), counts, n_cells, self.bits, out.ctypes.data, pos.ctypes.data)
        return out

    def height(self, idx: np.ndarray) -> np.ndarray:
        return ((self.key[idx] & ((1 << self.bits) - 1)) + self.base) * self.q

    def quantile(self, p: float) -> np.ndarray:
        """Per-cell quantile (linear interpolation between order statistics); NaN if empty."""
        out = np.full(self.counts.shape, np.nan)
        c, s = self.counts[self.has], self.starts[self.has]
        pos = p * (c - 1)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, c - 1)
        w = pos - lo
        out[self.has] = (1 - w) * self.height(s + lo) + w * self.height(s + hi)
        return out

    def mean_between(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Per-cell mean of the heights within [lo, hi]; NaN for empty cells."""
        cells = np.flatnonzero(self.has)
        base = cells.astype(np.int64) << self.bits
        top = (1 << self.bits) - 1
        qlo = np.clip(np.ceil(lo[cells] / self.q - 1e-9) - self.base, 0, top).astype(np.int64)
        qhi = np.clip(np.floor(hi[cells] / self.q + 1e-9) - self.base, 0, top).astype(np.int64)
        a = np.searchsorted(self.key, base | qlo, "left")
        b = np.searchsorted(self.key, base | qhi, "right")
        csum = _running_sum(self.key, top)
        out = np.full(self.counts.shape, np.nan)
        k = b - a
        out[cells] = (csum[b] - csum[a] + k * self.base) / np.maximum(k, 1) * self.q  # whole levels: exact
        out[cells[k == 0]] = np.nan
        return out


def _spare(z: np.ndarray, key: np.ndarray) -> bool:
    """Whether ``z`` (the caller's heights, spent once the keys are built) can hold the keys."""
    return z.dtype == np.float64 and z.flags.c_contiguous and len(z) == len(key) and not np.shares_memory(z, key)


def _sorted_halves(key: np.ndarray, out: np.ndarray, counts: np.ndarray, bits: int) -> np.ndarray:
    """``key`` sorted into ``out``: the cells before and after the middle point moved apart (in file
    order, where timsort finds its runs), each half sorted on its own thread (``key.sort()``'s bits)."""
    ends = np.cumsum(counts)
    cell = min(int(np.searchsorted(ends, ends[-1] // 2)) + 1, len(counts))
    split, limit = int(ends[cell - 1]), np.int64(cell) << bits
    lo, hi = 0, split
    for i in range(0, len(key), BLOCK):
        block = key[i : i + BLOCK]
        low = block < limit
        a, b = np.compress(low, block), np.compress(~low, block)
        out[lo : lo + len(a)], out[hi : hi + len(b)] = a, b
        lo, hi = lo + len(a), hi + len(b)
    other = threading.Thread(target=out[split:].sort, kwargs={"kind": "stable"}, name="soilvolume-sort")
    other.start()
    out[:split].sort(kind="stable")
    other.join()
    return out


def _mean(ids: np.ndarray, z: np.ndarray, counts: np.ndarray, n: int) -> np.ndarray:
    sums = np.bincount(ids, weights=z, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def _running_sum(key: np.ndarray, top: int) -> np.ndarray:
    """``[0, cumsum(key & top)]`` in float64, block by block from the running total (a whole
    cumsum's values), or by ``sv_running_sum``."""
    out = np.empty(len(key) + 1)
    lib = native.kernels()
    if lib is not None and key.dtype == np.int64 and key.flags.c_contiguous:
        lib.sv_running_sum(key.ctypes.data, len(key), top, out.ctypes.data)
        return out
    out[0] = 0.0
    for i in range(0, len(key), BLOCK):
        v = (key[i : i + BLOCK] & top).astype(np.float64)
        v[0] += out[i]
        np.cumsum(v, out=out[i + 1 : i + 1 + len(v)])
    return out


class OffsetSums:
    """Per-cell sums of the points' positions within their cells, gathered chunk by chunk."""

    def __init__(self, n_cells: int) -> None:
        self.sx, self.sy = np.zeros(n_cells), np.zeros(n_cells)
        self.seen = np.zeros(n_cells, bool)  # the cells :meth:`add_at` gave points (pages untouched: free)

    def add(self, ids: np.ndarray, col: np.ndarray, row: np.ndarray) -> None:
        """Points in flat cells ``ids`` at fractional grid coordinates ``col``/``row``."""
        self.sx += np.bincount(ids, weights=col - np.floor(col), minlength=self.sx.size)
        self.sy += np.bincount(ids, weights=row - np.floor(row), minlength=self.sy.size)

    def add_at(self, ids: np.ndarray, col: np.ndarray, row: np.ndarray) -> None:
        """:meth:`add` point by point, blocks giving the bits of one :meth:`add` of all: points of cells
        an earlier block gave points one by one (``np.add.at``, 10x slower), the others by a bincount."""
        old = self.seen[ids]
        self.seen[ids] = True
        if old.any():
            for sums, c in ((self.sx, col[old]), (self.sy, row[old])):
                np.add.at(sums, ids[old], (c - np.floor(c)).astype(np.float64))  # one dtype: numpy's fast path
            new = ~old
            ids, col, row = ids[new], col[new], row[new]
        for sums, c in ((self.sx, col), (self.sy, row)):
            sums += np.bincount(ids, weights=(c - np.floor(c)).astype(np.float64), minlength=sums.size)

    def means(self, counts: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
        """(east, north) mean offsets (m) from the cell centres, 0 where empty, (rows, cols) as ``counts``."""
        n = counts.ravel()
        with np.errstate(invalid="ignore", divide="ignore"):
            dx = np.where(n > 0, self.sx / n - 0.5, 0.0) * cell
            dy = np.where(n > 0, 0.5 - self.sy / n, 0.0) * cell
        return dx.reshape(counts.shape).astype(np.float32), dy.reshape(counts.shape).astype(np.float32)
