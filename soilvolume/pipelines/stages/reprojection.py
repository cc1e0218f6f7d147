"""filters.reprojection: PROJ transformation of X, Y and Z (traditional GIS axis order)."""

from __future__ import annotations

import numpy as np
import pyproj

from .view import PointView, StageContext


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
        x, y, z = tr.transform(view.arrays["X"], view.arrays["Y"], view.arrays["Z"], errcheck=False)
        x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
        ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
        view.arrays["X"], view.arrays["Y"], view.arrays["Z"] = x, y, z
        if not ok.all():
            view = view.take(ok)
    view.srs_wkt = dst.to_wkt()
    return view
