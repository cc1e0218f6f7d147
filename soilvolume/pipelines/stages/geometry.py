"""Crop geometries: PDAL bounds strings, WKT/GeoJSON polygons and points, and a fast vectorised
point-in-polygon test whose boundary counts as inside (GEOS ``covers``, as filters.crop uses)."""

from __future__ import annotations

import json
import re

import numpy as np

from ...core.cells import xy_in_box
from ...core.types import SoilVolumeError

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_bounds(value) -> tuple[tuple[float, float], ...]:
    """PDAL bounds ('([x0,x1],[y0,y1][,[z0,z1]])', a GeoJSON bbox list or a {minx..} object)
    as ((xmin, xmax), (ymin, ymax)[, (zmin, zmax)])."""
    if isinstance(value, str) and value.strip().startswith(("[", "{")):
        value = json.loads(value)
    if isinstance(value, dict):
        keys = ("x", "y", "z") if "minz" in value else ("x", "y")
        return tuple((float(value[f"min{k}"]), float(value[f"max{k}"])) for k in keys)
    if isinstance(value, list):
        v = [float(a) for a in value]
        if len(v) == 4:
            return ((v[0], v[2]), (v[1], v[3]))
        if len(v) == 6:
            return ((v[0], v[3]), (v[1], v[4]), (v[2], v[5]))
        raise SoilVolumeError(f"bounds {value!r}: a GeoJSON bbox has 4 or 6 numbers")
    pairs = re.findall(rf"\[\s*({_NUM})\s*,\s*({_NUM})\s*\]", str(value))
    if len(pairs) not in (2, 3) or not str(value).strip().startswith("("):
        raise SoilVolumeError(f"bounds '{value}': expected '([xmin, xmax], [ymin, ymax])'")
    return tuple((float(a), float(b)) for a, b in pairs)


def format_bounds(xmin: float, ymin: float, xmax: float, ymax: float) -> str:
    """PDAL's classic 2D bounds string."""
    return f"([{xmin!r}, {xmax!r}], [{ymin!r}, {ymax!r}])"


def _ring(text: str) -> np.ndarray:
    pts = [[float(t) for t in p.split()[:2]] for p in text.split(",") if p.strip()]
    return np.asarray(pts, dtype=np.float64)


def parse_polygon(value) -> list[np.ndarray]:
    """All rings (outer and holes, of every part) of a WKT or GeoJSON (Multi)Polygon."""
    if isinstance(value, str) and value.strip().startswith("{"):
        value = json.loads(value)
    if isinstance(value, dict):
        kind = value.get("type")
        coords = value.get("coordinates")
        polys = [coords] if kind == "Polygon" else coords if kind == "MultiPolygon" else None
        if polys is None:
            raise SoilVolumeError(f"polygon: GeoJSON type {kind!r} is not a (Multi)Polygon")
        return [np.asarray(r, dtype=np.float64)[:, :2] for p in polys for r in p]
    text = str(value).strip()
    head = text.split("(", 1)[0].strip().upper()
    if head.split()[0:1] not in (["POLYGON"], ["MULTIPOLYGON"]):
        raise SoilVolumeError(f"polygon '{text[:60]}': expected WKT POLYGON or MULTIPOLYGON")
    rings = [_ring(r) for r in re.findall(r"\(([^()]+)\)", text)]
    if not rings or any(len(r) < 3 for r in rings):
        raise SoilVolumeError(f"polygon '{text[:60]}': rings need at least 3 vertices")
    return rings


def parse_point(value) -> np.ndarray:
    """A WKT or GeoJSON 2D/3D point."""
    if isinstance(value, str) and value.strip().startswith("{"):
        value = json.loads(value)
    if isinstance(value, dict):
        return np.asarray(value["coordinates"], dtype=np.float64)
    m = re.fullmatch(r"\s*POINT\s*Z?\s*\(([^()]*)\)\s*", str(value), flags=re.IGNORECASE)
    if not m:
        raise SoilVolumeError(f"point '{value}': expected WKT like 'POINT(x y)' or 'POINT(x y z)'")
    return np.asarray([float(t) for t in m.group(1).split()], dtype=np.float64)


def covers(rings: list[np.ndarray], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon over all rings, boundary included.

    Only the points in the rings' bounding box are tested (a wide survey cropped to a small
    footprint sorts a fraction of its points): the others are outside, as the test finds them.
    """
    vertices = np.vstack(rings)
    box = xy_in_box(x, y, vertices.min(axis=0), vertices.max(axis=0))
    if box.all():
        return _covers(rings, x, y)
    out = np.zeros(x.shape[0], dtype=bool)
    idx = np.flatnonzero(box)
    out[idx] = _covers(rings, x[idx], y[idx])
    return out


def _covers(rings: list[np.ndarray], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """:func:`covers` of every point: the points are sorted by y once; each edge then only
    touches the points in its y band, so the cost is about (number of points) x (edges crossed
    by a horizontal line), not points x edges."""
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
