"""The embedded filters: filters.reprojection (PROJ, X, Y and Z in traditional GIS axis order),
filters.crop with one WKT ``polygon`` (the points it covers, its edges inside, as GEOS ``covers`` in
PDAL; :func:`soilvolume.core.polygons.covers`), filters.range with ``Dimension[lo:hi]`` limits and
filters.assign with ``Dimension = number``: the forms of the project's own pipelines
(``Classification[2:2]``, ``Classification = 0``); the other forms (open or negated ranges, WHERE
clauses, bounds, several polygons) need PDAL; filters.smrf and filters.csf: Classification 2 for ground,
1 for the rest, by the project's ground filters (:mod:`soilvolume.inputs.smrf`)."""

from __future__ import annotations

import re

import numpy as np
import pyproj

from ...core.polygons import covers
from ...core.types import SoilVolumeError
from ...inputs.smrf import DEFAULTS, csf_classify, smrf_classify
from .view import PointView, StageContext

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"\s*([A-Za-z_]\w*)\s*\[\s*({_NUM})?\s*:\s*({_NUM})?\s*\]\s*")
_VALUE = re.compile(rf"\s*([A-Za-z_]\w*)\s*=\s*({_NUM})\s*")


def _passing(view: PointView, text: str, ctx: StageContext) -> tuple[str, np.ndarray]:
    """(stored dimension name, mask of the points within) of one ``Dimension[lo:hi]`` range."""
    m = _RANGE.fullmatch(text)
    if not m:
        raise ctx.error(f"range '{text.strip()[:40]}' needs PDAL (without it only 'Dimension[lo:hi]')")
    name, lo, hi = m.groups()
    key = view.dim(name)
    if key is None:
        raise ctx.error(f"invalid dimension name '{name}' (the points have: {', '.join(view.arrays)})")
    values, ok = view.arrays[key], np.ones(len(view), dtype=bool)
    if lo is not None:
        ok &= values >= float(lo)
    if hi is not None:
        ok &= values <= float(hi)
    return key, ok


def filter_range(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The points passing ``limits``: ranges on one dimension ORed, different dimensions ANDed."""
    limits = [part for text in ctx.strings(opts, "limits") for part in text.split(",")]
    if not limits:
        raise ctx.error("option 'limits' is required")
    by_dim: dict[str, np.ndarray] = {}
    for text in limits:
        key, hit = _passing(view, text, ctx)
        by_dim[key] = by_dim[key] | hit if key in by_dim else hit
    return view.take(np.logical_and.reduce(list(by_dim.values())))


def assign(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """``value: "Dim = number"`` (no WHERE clause), applied in order."""
    for text in ctx.strings(opts, "value"):
        m = _VALUE.fullmatch(text)
        if not m:
            raise ctx.error(f"value '{text}' needs PDAL (without it only 'Dimension = number')")
        view.ensure(m.group(1))[:] = float(m.group(2))
    return view


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


def reproject(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """X/Y/Z from the points' SRS to ``out_srs``; Z transformed too, as PDAL does (a vertical unit in
    feet becomes metres); points whose transformation fails dropped."""
    out_text = opts.get("out_srs")
    if not out_text:
        raise ctx.error("option 'out_srs' is required")
    if not view.srs_wkt:
        raise ctx.error("the points have no SRS: set the reader's default_srs")
    src, dst = ctx.crs(view.srs_wkt, "the points' SRS: "), ctx.crs(out_text, "option 'out_srs': ")
    if len(view) and not src.equals(dst):
        try:
            tr = pyproj.Transformer.from_crs(src, dst, always_xy=True)
        except pyproj.exceptions.ProjError as exc:
            raise ctx.error(f"no transformation from {src.name} to {dst.name} ({exc})") from exc
        moved = tr.transform(*(view.arrays[d] for d in "XYZ"), errcheck=False)
        view.arrays.update(zip("XYZ", (np.asarray(a, dtype=np.float64) for a in moved), strict=True))
        ok = np.logical_and.reduce([np.isfinite(view.arrays[d]) for d in "XYZ"])
        if not ok.all():
            view = view.take(ok)
    view.srs_wkt = dst.to_wkt()
    return view


def _last_or_only(view: PointView, ctx: StageContext) -> np.ndarray:
    """The points SMRF classifies: last and single returns (all when the returns are not known)."""
    keys = view.dim("ReturnNumber"), view.dim("NumberOfReturns")
    if None in keys:
        return np.ones(len(view), dtype=bool)
    rn, nr = (view.arrays[key].astype(np.int64) for key in keys)
    zero = (rn == 0) | (nr == 0)
    if zero.all():
        return np.ones(len(view), dtype=bool)
    if zero.any():
        raise ctx.error("some NumberOfReturns or ReturnNumber values are 0, but not all")
    return ((rn == nr) & (nr > 1)) | (nr == 1)


def smrf(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """SMRF on the last and single returns, with PDAL's options and defaults."""
    cell = ctx.number(opts, "cell", 1.0, positive=True)
    params = {
        "cell": cell,
        "slope": ctx.number(opts, "slope", 0.15),
        "window": ctx.number(opts, "window", 18.0 * cell, positive=True),
        "threshold": ctx.number(opts, "threshold", 0.5),
        "scalar": ctx.number(opts, "scalar", 1.25),
    }
    cls = view.ensure("Classification")
    if len(view) == 0:
        return view
    use = _last_or_only(view, ctx)
    if not use.any():
        raise ctx.error("no returns to process")
    ground = smrf_classify(*(view.arrays[d][use] for d in "XYZ"), **params)
    cls[use] = np.where(ground, 2, 1).astype(cls.dtype)
    return view


def csf(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The cloth simulation filter on every point."""
    params = {  # numbers > 0 (rigidness checked below) of the type of their default
        key: type(value)(ctx.number(opts, key, value, positive=key != "rigidness"))
        for key, value in DEFAULTS.items()
        if key != "smooth"
    }
    smooth = opts.get("smooth", DEFAULTS["smooth"])  # true or false, or their text as PDAL reads it
    params["smooth"] = smooth if isinstance(smooth, bool) else str(smooth).lower() == "true"
    if params["rigidness"] not in (1, 2, 3):
        raise ctx.error("'rigidness' must be 1, 2 or 3")
    cls = view.ensure("Classification")
    if len(view) == 0:
        return view
    try:
        ground = csf_classify(view.arrays["X"], view.arrays["Y"], view.arrays["Z"], **params)
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    cls[:] = np.where(ground, 2, 1).astype(cls.dtype)
    return view
