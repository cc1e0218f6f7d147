"""Raster helpers of the report figures: block averaging of large grids and PNG encoding with
zlib (no imaging library)."""

from __future__ import annotations

import struct
import zlib

import numpy as np


def _fold(a: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Sums of k consecutive entries along ``axis`` (the last group may be shorter), added in turn."""
    a = np.moveaxis(a, axis, 0)
    out = np.zeros((-(-len(a) // k), *a.shape[1:]), np.float64 if a.dtype.kind == "f" else np.int32)
    for i in range(k):
        out[: len(a[i::k])] += a[i::k]
    return np.moveaxis(out, 0, axis)


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """NaN-aware mean over k x k blocks (partial blocks at the edges); NaN where a block has no data."""
    if k <= 1:
        return a
    ok = np.isfinite(a)
    total = _fold(_fold(np.where(ok, a, 0.0), k, 0), k, 1)
    count = _fold(_fold(ok, k, 0), k, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _block_any(m: np.ndarray, k: int) -> np.ndarray:
    m = np.asarray(m, bool)
    return m if k <= 1 else _fold(_fold(m, k, 0), k, 1) > 0


def _repeat(a: np.ndarray, f: int) -> np.ndarray:
    return a if f <= 1 else np.repeat(np.repeat(a, f, axis=0), f, axis=1)


def png_bytes(rgba: np.ndarray) -> bytes:
    """An (h, w, 4) uint8 array as an 8-bit RGBA PNG: every row but the first filtered by the
    row above it ("Up", zeros where a repeated row repeats it), fast zlib."""
    h, w = rgba.shape[:2]
    rows = np.ascontiguousarray(rgba, np.uint8).reshape(h, 4 * w)
    raw = np.empty((h, 1 + 4 * w), np.uint8)
    raw[:, 0] = 2
    raw[0] = np.r_[np.uint8(0), rows[0]]
    np.subtract(rows[1:], rows[:-1], out=raw[1:, 1:])  # modulo 256, as PNG's filter

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1))
        + chunk(b"IEND", b"")
    )
