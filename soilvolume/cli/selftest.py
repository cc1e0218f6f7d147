"""``soilvolume selftest --out DIR``: this installation checked on a tiny seeded pair."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..scenes.selftest import run_selftest
from .flags import add_progress, hooks, result

NAME = "selftest"


def add_parser(sub) -> None:
    """The sub-command: --out and --progress."""
    check = sub.add_parser(
        NAME,
        help="check this installation: every dependency imports, a tiny seeded pair is estimated",
        description="Import every dependency, write a seeded pair of a few thousand points (LAZ) "
        "and estimate it; exit 0 when the volumes are where they must be.",
    )
    check.add_argument("--out", type=Path, required=True, help="folder for the pair and its results")
    add_progress(check)


def run(ns: argparse.Namespace) -> int:
    """Run the check; print its findings as JSON (or send them through the protocol)."""
    return result(ns, run_selftest(ns.out, hooks(ns)))
