"""filters.crop: keep points inside (or, with ``outside``, outside) one bounds box, polygon or
point+distance region, with PDAL's edge rules."""

from __future__ import annotations

import numpy as np
import pyproj

from ...core.types import SoilVolumeError
from . import geometry
from .view import PointView, StageContext

OPTS = {"bounds", "polygon", "point", "distance", "outside", "a_srs"}


def _one(opts: dict, name: str, ctx: StageContext):
    value = opts.get(name)
    if isinstance(value, list) and value and not isinstance(value[0], (int, float)):
        if len(value) > 1:
            raise ctx.error(
                f"several '{name}' regions (PDAL makes one output view per region) "
                "are not supported by the embedded executor: give one region"
            )
        value = value[0]
    return value


def _transformer(view: PointView, opts: dict, ctx: StageContext):
    a_srs = ctx.string(opts, "a_srs")
    if not a_srs:
        return None
    if view.srs_wkt is None:
        raise ctx.error("unable to transform the crop geometry from 'a_srs': the points have no SRS")
    src, dst = pyproj.CRS.from_user_input(a_srs), pyproj.CRS.from_wkt(view.srs_wkt)
    if src.equals(dst):
        return None
    return pyproj.Transformer.from_crs(src, dst, always_xy=True)


def crop(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Bounds: closed box (2D, or 3D for a 3D box); polygon: GEOS covers (edges inside);
    point+distance: strictly closer than ``distance`` (circle for a 2D point, sphere for 3D)."""
    given = [k for k in ("bounds", "polygon", "point") if k in opts]
    if len(given) != 1:
        raise ctx.error("give exactly one of 'bounds', 'polygon' or 'point' (+ 'distance')")
    kind = given[0]
    x, y, z = view.arrays["X"], view.arrays["Y"], view.arrays["Z"]
    tr = _transformer(view, opts, ctx)
    try:
        if kind == "bounds":
            box = geometry.parse_bounds(_one(opts, "bounds", ctx))
            (x0, x1), (y0, y1) = box[0], box[1]
            if tr is not None:
                x0, y0, x1, y1 = tr.transform_bounds(x0, y0, x1, y1)
            keep = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            if len(box) == 3:
                keep &= (z >= box[2][0]) & (z <= box[2][1])
        elif kind == "polygon":
            rings = geometry.parse_polygon(_one(opts, "polygon", ctx))
            if tr is not None:
                rings = [np.column_stack(tr.transform(r[:, 0], r[:, 1])) for r in rings]
            keep = geometry.covers(rings, x, y)
        else:
            if tr is not None:
                raise ctx.error("'a_srs' with 'point' is not supported (PDAL does not reproject crop points either)")
            centre = geometry.parse_point(_one(opts, "point", ctx))
            dist = ctx.positive(opts, "distance")
            if dist is None:
                raise ctx.error("option 'point' requires 'distance'")
            d2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2
            if centre.shape[0] >= 3:
                d2 = d2 + (z - centre[2]) ** 2
            keep = d2 < dist * dist
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    except (ValueError, KeyError, TypeError) as exc:
        raise ctx.error(f"bad '{kind}' value ({exc})") from exc
    if ctx.boolean(opts, "outside", False):
        keep = ~keep
    return view.take(keep)
