"""``soilvolume volume BEFORE_DEM AFTER_DEM --out TIF``: cut, fill and net between two DEMs."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..workflow.rasters import run_volume_from_rasters
from .flags import add_progress, hooks, result

NAME = "volume"


def add_parser(sub) -> None:
    """The sub-command: the two DEMs, --out and the optional zones (it takes no table option)."""
    vol = sub.add_parser(NAME, help="cut/fill/net between two DEM GeoTIFFs (optional zones)")
    vol.add_argument("before_dem", type=Path)
    vol.add_argument("after_dem", type=Path)
    vol.add_argument("--out", type=Path, required=True, help="difference GeoTIFF to write")
    vol.add_argument("--zones", type=Path, help="polygon file (GeoPackage/Shapefile/GeoJSON)")
    vol.add_argument("--zone-field", help="attribute naming each zone")
    add_progress(vol)


def run(ns: argparse.Namespace) -> int:
    """Difference the DEMs; print the volumes as JSON (or send them through the protocol)."""
    res = run_volume_from_rasters(
        ns.before_dem, ns.after_dem, ns.out, zones=ns.zones, zone_field=ns.zone_field, hooks=hooks(ns)
    )
    return result(ns, res)
