"""Random site composer (issue 53): sites drawn at random from distributions of what the field
brings, each with a seed and exact truth, for measuring the engine on sites nobody described.

Two populations by seed range: :data:`DEV_SEEDS` to develop on, :data:`HELD_OUT_SEEDS` held out
and only measured (``bench/calibration.py``). ``compose(seed, directory)`` writes before.las,
after.las and truth.json (with the drawn description under ``description``).
"""

from __future__ import annotations

from pathlib import Path

from .describe import describe, kinds
from .draw import draw_site
from .epochs import epoch_points, write_site
from .site import Site

DEV_SEEDS = range(10_000, 20_000)  # the development population
HELD_OUT_SEEDS = range(90_000, 100_000)  # the held-out population: only measured

__all__ = ["DEV_SEEDS", "HELD_OUT_SEEDS", "Site", "compose", "describe", "draw_site", "epoch_points", "kinds"]


def compose(seed: int, directory) -> tuple[Path, Path, Path]:
    """Draw site ``seed`` and write its pair and truth into ``directory``."""
    return write_site(Site(draw_site(seed)), directory)
