"""filters.crop with one WKT ``polygon``: keep the points it covers (its edges inside, as GEOS
``covers`` in PDAL; :func:`soilvolume.core.polygons.covers`)."""

from __future__ import annotations

import re

import numpy as np

from ...core.polygons import covers
from ...core.types import SoilVolumeError
from .view import PointView, StageContext

OPTS = {"polygon"}


def _ring(text: str) -> np.ndarray:
    pts = [[float(t) for t in p.split()[:2]] for p in text.split(",") if p.strip()]
    return np.asarray(pts, dtype=np.float64)


def parse_polygon(value: str) -> list[np.ndarray]:
    """All rings (outer and holes, of every part) of a WKT POLYGON or MULTIPOLYGON."""
    text = str(value).strip()
    head = text.split("(", 1)[0].strip().upper()
    if head.split()[0:1] not in (["POLYGON"], ["MULTIPOLYGON"]):
        raise SoilVolumeError(f"polygon '{text[:60]}': expected WKT POLYGON or MULTIPOLYGON")
    rings = [_ring(r) for r in re.findall(r"\(([^()]+)\)", text)]
    if not rings or any(len(r) < 3 for r in rings):
        raise SoilVolumeError(f"polygon '{text[:60]}': rings need at least 3 vertices")
    return rings


def crop(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The points covered by ``polygon`` (holes and every part of a multipolygon honoured)."""
    value = opts.get("polygon")
    items = value if isinstance(value, list) else [value]
    if len(items) != 1 or not isinstance(items[0], str):
        raise ctx.error("needs one WKT 'polygon' (bounds, point regions, GeoJSON and several polygons need PDAL)")
    try:
        rings = parse_polygon(items[0])
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    except ValueError as exc:
        raise ctx.error(f"bad 'polygon' value ({exc})") from exc
    return view.take(covers(rings, view.arrays["X"], view.arrays["Y"]))
