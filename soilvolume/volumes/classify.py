"""Stage 3, the classification: the change areas (:mod:`.change`), what in them is not soil
(:mod:`.nonsoil`), the error model's stable ground away from the change."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..core.types import GridSpec
from ..options import Options
from .change import change_areas
from .correct import Corrected
from .nonsoil import exclude_nonsoil
from .refill import Refill
from .results import Epochs

MIN_QUIET = 12  # stable cells away from the change the error model needs, else it keeps them all


@dataclass(frozen=True)
class Areas:
    """The change areas counted (what is not soil left out), the class raster, report.json's ``excluded`` (with its
    terms, :func:`.nonsoil.exclude_nonsoil`), the stable ground."""

    fill: np.ndarray
    cut: np.ndarray
    classes: np.ndarray
    excluded: dict
    stable: np.ndarray
    counted: np.ndarray  # fill | cut: the change areas the headline sums


def classify(s: Refill, c: Corrected, epochs: Epochs, grid: GridSpec, options: Options) -> Areas:
    """The change areas, what is not soil in them, stable ground never in or next to them unless the user drew it."""
    fill, cut = change_areas(c.diff, c.lod_cell, refilled=s.filled_mask & ~s.seen_once)
    kept = exclude_nonsoil(s, c, (fill, cut), epochs, grid, options)
    quiet = c.stable & ~scipy.ndimage.binary_dilation(fill | cut, iterations=max(1, round(2.0 / grid.cell)))
    stable = quiet if not options.stable_mask and quiet.sum() >= MIN_QUIET else c.stable
    return Areas(*kept, stable, kept[0] | kept[1])
