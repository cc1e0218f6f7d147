"""filters.crop with one WKT ``polygon``: keep the points it covers (its edges inside, as GEOS
``covers`` in PDAL; :func:`soilvolume.core.polygons.covers`)."""

from __future__ import annotations

import re

import numpy as np

from ...core.polygons import covers
from .view import PointView, StageContext


def _rings(text: str, ctx: StageContext) -> list[np.ndarray]:
    """All rings (outer and holes, of every part) of a WKT POLYGON or MULTIPOLYGON."""
    if text.strip().split("(", 1)[0].upper().split()[0:1] not in (["POLYGON"], ["MULTIPOLYGON"]):
        raise ctx.error(f"polygon '{text.strip()[:60]}': expected WKT POLYGON or MULTIPOLYGON")
    try:
        rings = [
            np.array([[float(t) for t in p.split()[:2]] for p in r.split(",") if p.strip()], np.float64)
            for r in re.findall(r"\(([^()]+)\)", text)
        ]
    except ValueError as exc:
        raise ctx.error(f"bad 'polygon' value ({exc})") from exc
    if not rings or any(len(r) < 3 for r in rings):
        raise ctx.error(f"polygon '{text.strip()[:60]}': rings need at least 3 vertices")
    return rings


def crop(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The points covered by ``polygon`` (holes and every part of a multipolygon honoured)."""
    value = opts.get("polygon")
    items = value if isinstance(value, list) else [value]
    if len(items) != 1 or not isinstance(items[0], str):
        raise ctx.error("needs one WKT 'polygon' (bounds, point regions, GeoJSON and several polygons need PDAL)")
    return view.take(covers(_rings(items[0], ctx), view.arrays["X"], view.arrays["Y"]))
