"""``soilvolume pipeline``: both clouds' preparation as PDAL pipeline JSON, as the run prepares
them: the before cropped to the after's GPS footprint plus the radius, ground kept as the run keeps
it, no statistical outlier filter (the run has none; one moved a sparse pair's net by 1 to 2.6 %)."""

from __future__ import annotations

from pathlib import Path

from ..core.outputs import os_errors, output_dir
from ..core.wording import opt
from ..inputs.crs import lonlat_of, to_frame, work_frame
from ..inputs.footprint import footprint, polygon_wkt
from ..inputs.io import read_points
from ..inputs.prepare import resolve_crs
from ..options import Options
from .pipeline import build_prepare_pipeline, save_pipeline

#: what an emit folder may hold to be replaced: the files of an earlier emit and of its runs
EMITTED = ("before.json", "after.json", "before_prepared.laz", "after_prepared.laz")


def emit_pipelines(before: Path, after: Path, out_dir: Path, options: Options) -> tuple[Path, Path]:
    """Write ``before.json`` and ``after.json`` into ``out_dir``; returns their paths."""
    raw_b, raw_a = read_points(before), read_points(after)
    crs_b = resolve_crs(raw_b, options.before_crs, opt("before_crs"))
    crs_a = resolve_crs(raw_a, options.after_crs, opt("after_crs"))
    frame = work_frame(crs_b, lonlat_of(raw_b.xyz, crs_b) if crs_b.is_geographic else None)
    after_xy = to_frame(raw_a.xyz, crs_a, frame, raw_a.path)[:, :2] / frame.xy_unit
    poly = footprint(after_xy, options.radius / frame.xy_unit)
    srs = frame.crs.to_wkt()
    # --ground filter's SMRF as the run's (window in the frame's units; PDAL's defaults, 18 m and 0.15,
    # take the piles for objects)
    smrf = {"window": options.ground_window / frame.xy_unit, "slope": options.ground_slope}
    common = {"ground": options.ground, "out_srs": srs, "smrf": smrf if options.ground == "filter" else None}
    epochs = (("before", before, options.before_crs, polygon_wkt(poly)), ("after", after, options.after_crs, None))
    with output_dir(out_dir, [before, after], True, EMITTED) as out, os_errors(out.final):
        for name, path, in_srs, polygon in epochs:
            output = out.final / f"{name}_prepared.laz"
            stages = build_prepare_pipeline(path, in_srs=in_srs, polygon=polygon, output=output, **common)
            save_pipeline(stages, out.path(f"{name}.json"))
    return out.final / "before.json", out.final / "after.json"
