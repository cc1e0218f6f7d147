"""``soilvolume register BEFORE AFTER --out LAZ``: the after cloud moved onto the before one."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..workflow.commands import run_register
from .flags import add_options, add_progress, hooks, options_from, result

NAME = "register"


def add_parser(sub) -> None:
    """The sub-command: BEFORE, AFTER, --out and its options."""
    reg = sub.add_parser(NAME, help="register AFTER onto BEFORE and write it")
    reg.add_argument("before", type=Path)
    reg.add_argument("after", type=Path)
    reg.add_argument("--out", type=Path, required=True, help="registered after cloud (.las/.laz)")
    add_progress(reg)
    add_options(reg, NAME)


def run(ns: argparse.Namespace) -> int:
    """Register; print the transform and what was written as JSON (or send it through the protocol)."""
    return result(ns, run_register(ns.before, ns.after, ns.out, options_from(ns), hooks=hooks(ns)))
