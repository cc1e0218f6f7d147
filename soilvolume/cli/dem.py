"""``soilvolume dem CLOUD --out TIF``: one cloud to an average-height GeoTIFF."""

from __future__ import annotations

import argparse
from pathlib import Path

import pyproj

from ..inputs.crs import parse_crs
from ..inputs.stream import open_source
from ..validate import check_bounds
from ..workflow.commands import run_cloud_to_dem
from .flags import add_options, add_progress, hooks, options_from, result

NAME = "dem"


def add_parser(sub) -> None:
    """The sub-command: CLOUD, --out, --crs, --bounds (and their CRS) and its options."""
    dem = sub.add_parser(NAME, help="one cloud to an average-height GeoTIFF")
    dem.add_argument("cloud", type=Path, help="point cloud file")
    dem.add_argument("--out", type=Path, required=True, help="output GeoTIFF")
    dem.add_argument("--crs", help="CRS when the file has none")
    dem.add_argument(
        "--bounds",
        type=float,
        nargs=4,
        metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
        help="grid extent in the cloud's CRS, or in --bounds-crs (snapped outwards to the cell)",
    )
    dem.add_argument("--bounds-crs", help="CRS of --bounds when it is not the cloud's (e.g. EPSG:4326)")
    add_progress(dem)
    add_options(dem, NAME)


def run(ns: argparse.Namespace) -> int:
    """Grid the cloud; print what was written as JSON (or send it through the protocol)."""
    options, bounds = options_from(ns), check_bounds(ns.bounds)
    if bounds is not None and ns.bounds_crs:
        bounds = bounds_in_cloud_crs(ns.cloud, ns.crs, bounds, ns.bounds_crs)
    return result(ns, run_cloud_to_dem(ns.cloud, ns.out, options, crs=ns.crs, bounds=bounds, hooks=hooks(ns)))


def bounds_in_cloud_crs(cloud: Path, crs: str | None, bounds: tuple, bounds_crs: str) -> tuple:
    """``bounds`` (in ``bounds_crs``) as the box around them in the cloud's CRS (``crs`` when
    given, else its header's); unchanged when the cloud has no CRS."""
    wkt = crs or open_source(cloud).crs_wkt
    if not wkt:
        return bounds
    to = pyproj.Transformer.from_crs(parse_crs(bounds_crs, "--bounds-crs"), parse_crs(wkt, str(cloud)), always_xy=True)
    return check_bounds(to.transform_bounds(*bounds))
