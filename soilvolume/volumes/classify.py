"""Stage 3 of the volume step, the classification: the areas of significant change
(:mod:`.change`), what in them is not soil left out and listed (:mod:`.nonsoil`), and the
stable ground of the error model kept away from the change."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from .change import change_areas
from .correct import Corrected
from .nonsoil import Exclusion, exclude_nonsoil
from .refill import Refill

MIN_QUIET = 12  # stable cells away from the change the error model needs, else it keeps them all


@dataclass(frozen=True)
class Areas:
    """The change areas counted (fill, cut: moved objects and what is not soil left out), what
    was left out (``exclusion``) and the stable ground of the error model."""

    fill: np.ndarray
    cut: np.ndarray
    exclusion: Exclusion
    stable: np.ndarray

    @property
    def counted(self) -> np.ndarray:
        """The change areas the headline sums."""
        return self.fill | self.cut


def classify(s: Refill, c: Corrected, epochs: tuple[EpochDEM, EpochDEM], grid: GridSpec, options: Options) -> Areas:
    """The change areas of the corrected difference and what is not soil in them; ``epochs``:
    after, before. Stable ground for the error model is never a cell of (or next to) a detected
    change area, unless the user drew it."""
    refilled = s.filled_mask & ~s.seen_once
    fill, cut = change_areas(c.diff, c.lod_cell, refilled=refilled)
    ex = exclude_nonsoil(c.diff, (fill, cut), epochs, c.offset, grid, options, s.heights, c.stable, refilled)
    quiet = c.stable & ~scipy.ndimage.binary_dilation(fill | cut, iterations=max(1, round(2.0 / grid.cell)))
    stable = quiet if not options.stable_mask and quiet.sum() >= MIN_QUIET else c.stable
    return Areas(ex.fill, ex.cut, ex, stable)
