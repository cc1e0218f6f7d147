"""Points to the cells of a regular grid: the one ``floor((v - lo) / cell)`` binning shared by the
registration's column surfaces and the embedded PDAL stages; a grid's sums over blocks of cells."""

from __future__ import annotations

import numpy as np

from .. import native


def block_sums(a: np.ndarray, k: int) -> np.ndarray:
    """Sums over the k x k blocks of a 2-D array (partial blocks at the edges): float64 for floats, else int32."""
    return _fold(_fold(a, k, 0), k, 1)


def _fold(a: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Sums of k consecutive entries along ``axis`` (the last group may be shorter), added in turn."""
    a = np.moveaxis(a, axis, 0)
    out = np.zeros((-(-len(a) // k), *a.shape[1:]), np.float64 if a.dtype.kind == "f" else np.int32)
    for i in range(k):
        out[: len(a[i::k])] += a[i::k]
    return np.moveaxis(out, 0, axis)


def cell_index(v: np.ndarray, lo, cell: float) -> np.ndarray:
    """``floor((v - lo) / cell)`` as int64, for one axis (scalar ``lo``) or (N, k) coordinates; off the
    grid the indices are negative or too large: callers drop or clip them."""
    return np.floor((v - lo) / cell).astype(np.int64)


def in_box(xyz: np.ndarray, lo, hi) -> np.ndarray:
    """Mask of the points whose x/y lie in the box lo..hi (edges included): the same as
    ``((xyz[:, :2] >= lo) & (xyz[:, :2] <= hi)).all(axis=1)``, without its (N, 2) temporaries."""
    return xy_in_box(xyz[:, 0], xyz[:, 1], lo, hi)


def xy_in_box(x: np.ndarray, y: np.ndarray, lo, hi) -> np.ndarray:
    """:func:`in_box` of coordinates given as separate x and y arrays."""
    return (x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])


def bounds(xyz: np.ndarray, dims: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-column (min, max) of the first ``dims`` columns: ``xyz.min(axis=0)``, ``xyz.max(axis=0)``, ~10x
    faster (numpy's reduction over axis 0 of a narrow array steps k values at a time)."""
    k = xyz.shape[1] if dims is None else dims
    if xyz.dtype == np.float64 and len(xyz) >= NATIVE_BOUNDS and 0 < k <= 3:
        fast = _native_bounds(xyz, k)
        if fast is not None:
            return fast
    lo = np.array([xyz[:, j].min() for j in range(k)])
    hi = np.array([xyz[:, j].max() for j in range(k)])
    return lo, hi


NATIVE_BOUNDS = 50_000  # fewest points whose bounds the native kernel takes (a call costs ~10 us)


def _native_bounds(xyz: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`bounds` on the kernel (``sv_bounds``: one pass over the points), None without it."""
    lib, walk = native.kernels(), native.steps(xyz, np.float64)
    if lib is None or walk is None:
        return None
    lo, hi = np.empty(k), np.empty(k)
    step, axis = walk
    lib.sv_bounds(xyz.ctypes.data, len(xyz), step, axis, k, lo.ctypes.data, hi.ctypes.data)
    return lo, hi


def rows(xyz: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The rows of ``xyz`` where ``mask`` is true: ``xyz[mask]``, ~2x faster for (N, k) arrays."""
    return np.compress(mask, xyz, axis=0)
