"""``soilvolume estimate BEFORE AFTER --out DIR``: the whole pipeline."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..reporting import summary
from ..reporting.report import summary_lines
from ..workflow.estimate import run_estimate
from .flags import add_options, add_progress, hooks, options_from, result

NAME = "estimate"
EPILOG = """Outputs in DIR: dem_before.tif, dem_after.tif (average-height DEMs, refilled heights where
filled_mask.tif is 1), difference.tif (H_after - H_before - correction: dem_after - dem_before -
plane_offset), plane_offset.tif (the correction d_i), filled_mask.tif,
excluded.tif (what is not soil: vegetation, objects, moved objects; see --exclude),
report.json, report.html, and with --registered-cloud after_registered.laz.
change_areas.geojson and .gpkg: the areas of significant change as cut and fill polygons with their volumes.
With --contour-interval M also contours.gpkg (layers difference, dem_before, dem_after: lines every M m);
with --zones also zones.gpkg and zones.csv; with --sections LINES sections.csv and sections/NAME.svg.
Volumes are in cubic metres: fill = material added, cut = removed,
net = fill - cut. Lengths are metres in the before cloud's CRS (vertical feet are converted).
The outputs appear together or not at all; exit status 0 (done), 1 (error, one line on stderr),
2 (bad command line), 130/143 (interrupted by SIGINT/SIGTERM; nothing written)."""


def add_parser(sub) -> None:
    """The sub-command: BEFORE, AFTER, --out, the pipelines, --registered-cloud and its options."""
    est = sub.add_parser(
        NAME,
        help="the whole pipeline: register, grid, difference, volumes",
        description="Estimate the soil volume change from BEFORE to AFTER.",
        epilog=EPILOG,
    )
    est.add_argument(
        "before",
        type=Path,
        help="wide 'before' survey (LAS/LAZ, COPC, VPC of tiles, PLY/PCD/XYZ) or a design: a DEM GeoTIFF (.tif) "
        "or a LandXML TIN (.xml, .landxml)",
    )
    est.add_argument("after", type=Path, help="smaller 'after' survey (the same formats)")
    est.add_argument(
        "--out", type=Path, required=True, help="output folder (created; must be empty unless --overwrite)"
    )
    est.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output folder of an earlier run as a whole, in one swap (refused when it "
        "holds files a run does not write)",
    )
    est.add_argument(
        "--before-pipeline",
        type=Path,
        help="PDAL pipeline JSON preparing the before cloud (replaces reading it); its writers "
        "write into --out under their file names, never onto an input",
    )
    est.add_argument("--after-pipeline", type=Path, help="PDAL pipeline JSON preparing the after cloud")
    est.add_argument(
        "--registered-cloud",
        action="store_true",
        help="also write after_registered.laz, the after cloud moved by the registration (off by "
        "default: it costs as much as the rest of a large run; report.json has the 4x4 transform)",
    )
    est.add_argument("--quiet", action="store_true", help="no progress output")
    add_progress(est)
    add_options(est, NAME)


def run(ns: argparse.Namespace) -> int:
    """Estimate; print the summary (or send the result through the protocol)."""
    res = run_estimate(
        ns.before,
        ns.after,
        ns.out,
        options_from(ns),
        overwrite=ns.overwrite,
        hooks=hooks(ns),
        before_pipeline=ns.before_pipeline,
        after_pipeline=ns.after_pipeline,
    )
    data = {"report": res.report, "outputs": res.outputs, "summary": front_end_summary(res.keyed or res.report)}
    return result(ns, data, [*summary_lines(res.report), f"outputs in {ns.out}"])


def front_end_summary(report: dict) -> dict:
    """The figures a front end shows beside report.json: rotation and shift, the verdict, the
    significance in words (each zone's ± is in report.json's zones)."""
    local = (report.get("registration") or {}).get("transform_local")
    return {
        **(summary.rotation_shift(local) if local is not None else {}),
        "quality": summary.quality(report),
        "significance": summary.significance(report),
    }
