"""Cloud-Optimized Point Clouds (``.copc.laz``) through laspy's COPC reader: read whole like any
LAZ, or only the octree nodes meeting an x/y box, down to the level of a ``resolution`` (thinned)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError
from .records import decoded_points


def is_copc(path: str | Path) -> bool:
    """Whether ``path`` is a COPC file (by its name, then by its first VLR)."""
    p = Path(path)
    if p.name.lower().endswith(".copc.laz"):
        return True
    if p.suffix.lower() != ".laz":
        return False
    try:
        with open(p, "rb") as f:
            head = f.read(375 + 54 + 160)
    except OSError:
        return False
    return len(head) > 377 + 20 and head[377 : 377 + 4] == b"copc"  # user id of the first VLR (LAS 1.4)


def read_fraction(path: str | Path, lo=None, hi=None, resolution: float | None = None) -> float:
    """The share of the points of the nodes meeting the box a read at ``resolution`` returns, from the
    octree hierarchy alone: what scales a thinned read's counts back to the survey's density."""
    import laspy
    from laspy.copc import load_octree_for_query

    if resolution is None:
        return 1.0
    with laspy.CopcReader.open(str(path)) as reader:
        bounds = _bounds(lo, hi)
        if bounds is not None:
            bounds = bounds.ensure_3d(reader.header.mins, reader.header.maxs)
        args = (reader.source, reader.copc_info, reader.root_page, bounds)
        every = sum(n.point_count for n in load_octree_for_query(*args))
        levels = range(0, max(1, math.ceil(math.log2(reader.copc_info.spacing / resolution)) + 1))  # as laspy's
        read = sum(n.point_count for n in load_octree_for_query(*args, levels))
    return read / every if every else 1.0


def copc_chunks(
    path: str | Path, lo=None, hi=None, resolution=None, size: int = 1_000_000, signals=False, origin=None
) -> Iterator[tuple]:
    """(absolute xyz float64 minus ``origin``, classification or None[, signals]) of a COPC file's
    points within the x/y box lo..hi, at most ``size`` at a time, from the octree nodes meeting it
    (down to the level of ``resolution``)."""
    import laspy

    try:
        with laspy.CopcReader.open(str(path)) as reader:
            pts = reader.query(bounds=_bounds(lo, hi), resolution=resolution)
            dims = set(reader.header.point_format.dimension_names)
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable COPC file ({exc})") from exc
    for i in range(0, len(pts), size):
        yield decoded_points(pts[i : i + size], dims, signals, origin)


def _bounds(lo, hi):
    """laspy's query box of the x/y box lo..hi (None: everything)."""
    import laspy

    return None if lo is None else laspy.copc.Bounds(mins=np.asarray(lo[:2], float), maxs=np.asarray(hi[:2], float))
