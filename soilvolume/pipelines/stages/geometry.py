"""Crop geometries: PDAL bounds strings, WKT/GeoJSON polygons and points; the point-in-polygon
test whose boundary counts as inside (GEOS ``covers``, as filters.crop uses) is
:func:`soilvolume.core.polygons.covers`."""

from __future__ import annotations

import json
import re

import numpy as np

from ...core.polygons import _covers, covers  # noqa: F401  (their home was this module)
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
