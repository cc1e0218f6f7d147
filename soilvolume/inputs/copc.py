"""Cloud-Optimized Point Clouds (``.copc.laz``): bounded reads through laspy's COPC reader.

A COPC file is also a valid LAZ 1.4 file, so a whole-file read streams it like any LAZ; a read
within an x/y box fetches and decompresses only the octree nodes meeting the box, and a
``resolution`` stops at the octree level with that point spacing (a thinned read).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError
from .records import point_signals


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


def _levels(reader, resolution: float | None) -> range | None:
    """The octree levels a read at ``resolution`` (point spacing, file units) needs, as laspy
    computes them; None for all."""
    import math

    if resolution is None:
        return None
    return range(0, max(1, math.ceil(math.log2(reader.copc_info.spacing / resolution)) + 1))


def read_fraction(path: str | Path, lo=None, hi=None, resolution: float | None = None) -> float:
    """The share of the points of the nodes meeting the box that a read at ``resolution`` returns,
    from the octree hierarchy alone (1.0 for a full-resolution read): what scales the counts of a
    thinned read back to the survey's density."""
    import laspy
    from laspy.copc import load_octree_for_query

    if resolution is None:
        return 1.0
    with laspy.CopcReader.open(str(path)) as reader:
        bounds = None
        if lo is not None:
            bounds = laspy.copc.Bounds(mins=np.asarray(lo[:2], float), maxs=np.asarray(hi[:2], float))
            bounds = bounds.ensure_3d(reader.header.mins, reader.header.maxs)
        args = (reader.source, reader.copc_info, reader.root_page, bounds)
        every = sum(n.point_count for n in load_octree_for_query(*args))
        read = sum(n.point_count for n in load_octree_for_query(*args, _levels(reader, resolution)))
    return read / every if every else 1.0


def copc_chunks(
    path: str | Path,
    lo=None,
    hi=None,
    resolution: float | None = None,
    size: int = 1_000_000,
    signals: bool = False,
) -> Iterator[tuple]:
    """(absolute xyz float64, classification or None) of the points of a COPC file within the
    x/y box lo..hi (inclusive), at most ``size`` at a time, read from the octree nodes meeting
    the box (down to the level of ``resolution`` when given); with ``signals`` also their colour
    and returns (:func:`records.point_signals`)."""
    import laspy

    try:
        with laspy.CopcReader.open(str(path)) as reader:
            bounds = None
            if lo is not None:
                bounds = laspy.copc.Bounds(mins=np.asarray(lo[:2], float), maxs=np.asarray(hi[:2], float))
            pts = reader.query(bounds=bounds, resolution=resolution)
            dims = set(reader.header.point_format.dimension_names)
            has_cls = "classification" in dims
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable COPC file ({exc})") from exc
    for i in range(0, len(pts), size):
        part = pts[i : i + size]
        xyz = np.empty((len(part), 3))
        xyz[:, 0], xyz[:, 1], xyz[:, 2] = part.x, part.y, part.z
        cls = np.array(part.classification) if has_cls else None
        yield (xyz, cls, point_signals(part, dims)) if signals else (xyz, cls)
