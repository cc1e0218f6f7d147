"""A triangulated surface rasterised in numpy at a grid's cell centres: barycentric inside each
triangle, NaN outside, over the cells of the triangles' boxes in chunks of bounded memory."""

from __future__ import annotations

import numpy as np

CHUNK = 4_000_000  # candidate cells per chunk (about 200 MB of temporaries)
EPS = 1e-9  # barycentric tolerance: a centre on a shared edge belongs to both triangles


def rasterise(uv: np.ndarray, z: np.ndarray, faces: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Heights at the integer (col, row) positions of a ``shape`` grid of the points ``uv`` (col, row
    in cells), heights ``z``, triangles ``faces`` (m, 3)."""
    out = np.full(shape, np.nan)
    tri = uv[faces]  # (m, 3, 2)
    c0 = np.maximum(np.ceil(tri[..., 0].min(axis=1) - EPS), 0).astype(np.int64)
    c1 = np.minimum(np.floor(tri[..., 0].max(axis=1) + EPS), shape[1] - 1).astype(np.int64)
    r0 = np.maximum(np.ceil(tri[..., 1].min(axis=1) - EPS), 0).astype(np.int64)
    r1 = np.minimum(np.floor(tri[..., 1].max(axis=1) + EPS), shape[0] - 1).astype(np.int64)
    width, height = np.maximum(c1 - c0 + 1, 0), np.maximum(r1 - r0 + 1, 0)
    count = width * height
    keep = np.flatnonzero(count > 0)
    cum, start = np.cumsum(count[keep]), 0
    while start < len(keep):
        done = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, done + CHUNK, side="right")))
        part = keep[start:stop]
        _fill(out, tri[part], z[faces[part]], c0[part], r0[part], width[part], count[part])
        start = stop
    return out


def _fill(out, tri, zt, c0, r0, width, count) -> None:
    """Write the heights of the cells inside triangles ``tri`` (k, 3, 2) with corner heights ``zt``."""
    t = np.repeat(np.arange(len(count)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    col, row = c0[t] + k % width[t], r0[t] + k // width[t]
    a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    px, py = col - a[:, 0], row - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        w1 = (px * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * py) / det
        w2 = ((b[:, 0] - a[:, 0]) * py - px * (b[:, 1] - a[:, 1])) / det
    w0 = 1.0 - w1 - w2
    inside = (w0 >= -EPS) & (w1 >= -EPS) & (w2 >= -EPS) & (det != 0)
    zs = w0 * zt[t, 0] + w1 * zt[t, 1] + w2 * zt[t, 2]
    out[row[inside], col[inside]] = zs[inside]
