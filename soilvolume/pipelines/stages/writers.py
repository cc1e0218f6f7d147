"""writers.las through :func:`soilvolume.inputs.io.write_las`."""

from __future__ import annotations

from pathlib import Path

from ...inputs import io
from .view import PointView, StageContext


def write_las(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """LAS 1.4 / LAZ by suffix; one scale for X/Y/Z (PDAL's default 0.01), automatic offsets."""
    name = opts.get("filename")
    if not name:
        raise ctx.error("option 'filename' is required")
    if "#" in name:
        raise ctx.error("'#' placeholders (one file per view) need PDAL")
    path = Path(name)
    scales = {ctx.number(opts, f"scale_{a}", 0.01) for a in "xyz"}
    if len(scales) != 1:
        raise ctx.error("different scale_x/scale_y/scale_z need PDAL")
    try:
        io.write_las(path, view.xyz, view.srs_wkt, view.arrays.get("Classification"), scale=scales.pop())
    except OSError as exc:
        raise ctx.error(f"{path}: cannot write ({exc})") from exc
    return view
