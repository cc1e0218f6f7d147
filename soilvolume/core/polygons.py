"""A fast vectorised point-in-polygon test whose boundary counts as inside (GEOS ``covers``): the
footprint crop and PDAL's filters.crop (:mod:`soilvolume.pipelines.stages.filters`) share it."""

from __future__ import annotations

import numpy as np

from .cells import xy_in_box


def covers(rings: list[np.ndarray], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon over all rings, boundary included; only the points in the rings'
    box are tested (a wide survey cropped to a small footprint sorts a fraction of its points)."""
    vertices = np.vstack(rings)
    box = xy_in_box(x, y, vertices.min(axis=0), vertices.max(axis=0))
    if box.all():
        return _covers(rings, x, y)
    out = np.zeros(x.shape[0], dtype=bool)
    idx = np.flatnonzero(box)
    out[idx] = _covers(rings, x[idx], y[idx])
    return out


def _covers(rings: list[np.ndarray], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """:func:`covers` of every point, sorted by y once: each edge touches only its y band's points
    (cost: points x edges crossed by a horizontal line, not points x edges)."""
    n = x.shape[0]
    order = np.argsort(y, kind="stable")
    ys, xs = y[order], x[order]
    inside = np.zeros(n, dtype=bool)
    boundary = np.zeros(n, dtype=bool)
    for ring in rings:
        pts = ring if np.array_equal(ring[0], ring[-1]) else np.vstack([ring, ring[:1]])
        for (x1, y1), (x2, y2) in zip(pts[:-1], pts[1:], strict=True):
            lo, hi = (y1, y2) if y1 <= y2 else (y2, y1)
            a = np.searchsorted(ys, lo, "left")
            b = np.searchsorted(ys, hi, "right")
            if a == b:
                continue
            px, py = xs[a:b], ys[a:b]
            # on the edge: collinear and inside the segment's box
            cross = (x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)
            on = (cross == 0) & (px >= min(x1, x2)) & (px <= max(x1, x2))
            boundary[a:b] |= on
            if y1 != y2:  # crossing number: half-open in y, ray towards +x
                band = (py >= lo) & (py < hi)
                xint = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
                inside[a:b] ^= band & (px < xint)
    out = np.empty(n, dtype=bool)
    out[order] = inside | boundary
    return out
