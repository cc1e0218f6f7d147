"""``soilvolume pipeline BEFORE AFTER --emit DIR``: the PDAL pipelines that prepare both clouds."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..pipelines.emit import emit_pipelines
from .flags import add_options, options_from

NAME = "pipeline"


def add_parser(sub) -> None:
    """The sub-command: BEFORE, AFTER, --emit and its options."""
    pipe = sub.add_parser(
        NAME,
        help="write the PDAL pipelines that prepare both clouds",
        description="Write before.json and after.json: read, reproject to the before CRS, crop the before "
        "cloud to the after footprint + radius, select ground as the estimate does; run them with "
        "`pdal pipeline` or pass them to `soilvolume estimate --before-pipeline/--after-pipeline`.",
    )
    pipe.add_argument("before", type=Path)
    pipe.add_argument("after", type=Path)
    pipe.add_argument("--emit", type=Path, required=True, help="folder for the two pipeline JSON files")
    add_options(pipe, NAME)


def run(ns: argparse.Namespace) -> int:
    """Write the two pipelines; print their paths."""
    for path in emit_pipelines(ns.before, ns.after, ns.emit, options_from(ns)):
        print(path)
    return 0
