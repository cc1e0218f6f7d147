"""``soilvolume stockpile SURVEY [--piles FILE] --out DIR``: one survey's stockpile inventory."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..workflow.stockpile import PileInput, run_stockpile
from .flags import add_options, add_progress, hooks, options_from, result

NAME = "stockpile"


def add_parser(sub) -> None:
    """The sub-command: SURVEY, --piles and its fields, --out, --crs and its options (--base, --density, ...)."""
    p = sub.add_parser(NAME, help="stockpile inventory of one survey: each pile's volume, interval and tonnes")
    p.add_argument("survey", type=Path, help="point cloud file (LAS/LAZ, COPC, PLY, text)")
    p.add_argument(
        "--piles",
        type=Path,
        help="toe polygons, any OGR vector file (GeoPackage, Shapefile, GeoJSON, ...); the polygon is the mask. "
        "Without it, the piles are found as regions rising above the surrounding ground and their outlines written",
    )
    p.add_argument("--name-field", help="the polygons' name field (default: a field called name, pile, label or id)")
    p.add_argument("--density-field", help="the polygons' bulk density field (t/m3), before --density")
    p.add_argument("--out", type=Path, required=True, help="output folder (created; must be empty unless --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace an output folder of an earlier run")
    p.add_argument("--crs", help="CRS of the survey when its file has none")
    p.add_argument("--pipeline", type=Path, help="PDAL pipeline JSON preparing the survey")
    add_progress(p)
    add_options(p, NAME)


def run(ns: argparse.Namespace) -> int:
    """Measure the piles; print what was written as JSON (or send it through the protocol)."""
    piles = PileInput(ns.piles, ns.name_field, ns.density_field)
    given = {"crs": ns.crs, "pipeline": ns.pipeline, "piles": piles, "overwrite": ns.overwrite, "hooks": hooks(ns)}
    return result(ns, run_stockpile(ns.survey, ns.out, options_from(ns), **given))
