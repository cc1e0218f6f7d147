"""``soilvolume demo``: a seeded synthetic pair with known volumes, made and estimated."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..scenes.demo import run_demo

NAME = "demo"


def add_parser(sub) -> None:
    """The sub-command: --out, --size, --seed."""
    demo = sub.add_parser(NAME, help="make a seeded synthetic pair with known volumes and run it")
    demo.add_argument("--out", type=Path, default=Path("demo_out"), help="folder for the pair and results")
    demo.add_argument("--size", choices=("small", "paper"), default="small", help="scene size")
    demo.add_argument("--seed", type=int, default=0, help="scene seed")


def run(ns: argparse.Namespace) -> int:
    """Make the pair and estimate it; the exit status says whether the volumes are right."""
    return run_demo(ns.out, ns.size, ns.seed)
