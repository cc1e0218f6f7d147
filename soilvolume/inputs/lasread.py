"""LAS/LAZ/COPC files read chunk by chunk: whole, by point ranges (LAZ seeks by its chunk table)
or, through laspy's COPC reader, by the octree nodes meeting an x/y box, down to the level of a
``resolution`` (thinned); and their headers."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError, short_error
from .records import decoded_points, las_chunks

CRS_RECORDS = {2111, 2112, 34735, 34736, 34737}  # WKT (math transform, CRS) and GeoTIFF keys
WKT_STARTS = (b"PROJCS", b"PROJCRS", b"GEOGCS", b"GEOGCRS", b"COMPD_CS", b"COMPOUNDCRS", b"GEODCRS")


def _looks_like_crs(vlr) -> bool:
    """A VLR that was meant to hold the CRS: its ids, or WKT-looking content."""
    from difflib import SequenceMatcher

    user = str(getattr(vlr, "user_id", "")).strip("\x00 ")
    if SequenceMatcher(None, user.lower(), "lasf_projection").ratio() > 0.8 or vlr.record_id in CRS_RECORDS:
        return True
    data = getattr(vlr, "record_data", b"") or b""
    return bytes(data[:16]).lstrip().upper().startswith(WKT_STARTS)


def las_header(p: Path) -> tuple:
    """(CRS WKT or None, count, mins, maxs, has a classification, compressed) of a LAS/LAZ/COPC header;
    its CRS (WKT VLR or GeoTIFF keys) None without any, an unreadable one an error."""
    import laspy

    try:
        with laspy.open(p) as reader:
            h = reader.header
            try:
                crs = h.parse_crs()
            except Exception as exc:  # laspy raises several types on broken VLRs
                raise SoilVolumeError(f"{p}: the CRS stored in the header cannot be read ({short_error(exc)})") from exc
            broken = None if crs is not None else next((v for v in h.vlrs if _looks_like_crs(v)), None)
            if broken is not None:
                user = "".join(c if c.isprintable() else "?" for c in str(broken.user_id))
                raise SoilVolumeError(
                    f"{p}: the header's CRS record (VLR '{user}' {broken.record_id}) cannot be read (corrupt header?)"
                )
            dims = set(h.point_format.dimension_names)
            lo, hi = np.asarray(h.mins, float), np.asarray(h.maxs, float)
            wkt = None if crs is None else crs.to_wkt()
            return wkt, int(h.point_count), lo, hi, "classification" in dims, bool(h.are_points_compressed)
    except SoilVolumeError:
        raise
    except Exception as exc:
        raise SoilVolumeError(f"{p}: not a readable LAS/LAZ file ({short_error(exc)})") from exc


def las_ranges(
    path: str, ranges: list[tuple[int, int]], size: int, signals: bool | Callable = False, origin=None
) -> Iterator[tuple]:
    """Chunks of the (start, count) point ranges of a LAS/LAZ file (LAZ seeks by its chunk table)."""
    import laspy

    try:
        with laspy.open(path) as reader:
            dims = set(reader.header.point_format.dimension_names)
            for start, count in ranges:
                reader.seek(start)
                for i in range(0, count, size):
                    yield decoded_points(reader.read_points(min(size, count - i)), dims, signals, origin)
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc


def file_chunks(
    path: str, region, size: int, resolution: float | None = None, signals: bool | Callable = False, origin=None
) -> Iterator[tuple]:
    """Chunks of one LAS/LAZ/COPC file (:meth:`Source.chunks`): of a COPC file with a ``region`` or a
    ``resolution``, only the octree nodes meeting it, down to that spacing; else the whole file."""
    if (region is not None or resolution is not None) and is_copc(path):
        lo, hi = region if region is not None else (None, None)
        yield from copc_chunks(path, lo, hi, resolution, size, bool(signals), origin)
        return
    yield from las_chunks(Path(path), las_header(Path(path))[1], size, signals, origin)


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
