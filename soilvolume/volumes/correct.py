"""Stage 2, the correction: the bias found on stable ground (a tile is given the overview's)
subtracted, each cell's level of detection, holes across the outline refilled (:mod:`.holes.works`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compensation.correction import MODES
from ..compensation.correction import apply as apply_correction
from ..compensation.robust import patches
from ..core.types import GridSpec
from ..options import Options
from .change import MIN_CELLS, cell_lod, cell_sigma
from .holes.works import refill_across_outline
from .refill import Refill, refill_sigma
from .results import Epochs, Given
from .uncertainty import detection_level, z_value
from .zones import polygons_mask


@dataclass(frozen=True)
class Corrected:
    """The corrected difference and what the next stages take from the correction."""

    offset: np.ndarray  # the correction subtracted (m)
    params: dict  # its parameters
    stable: np.ndarray  # the stable ground it was found on
    tile: bool  # a window of a tiled run, given the overview's correction
    core: tuple[slice, slice]  # the cells the budgets count (a tile's core; the halo is context)
    diff: np.ndarray  # the corrected difference, holes across the outline refilled side by side
    filled: np.ndarray  # the same before the correction: diff + offset
    fill_sigma: np.ndarray  # the refilled cells' one-sigma error (m)
    lod: float  # the stable ground's level of detection (m)
    lod_cell: np.ndarray  # each cell's (m)
    outline: np.ndarray  # the side-by-side refill minus the plain one (m; 0 elsewhere)


def correct(s: Refill, epochs: Epochs, d_i, grid: GridSpec, options: Options, given: Given | None) -> Corrected:
    """The correction of the refilled difference (see module); ``given``: a tiled run's window."""
    if given is None:  # stable ground found alike for every method; ``paper-plane`` takes ``d_i`` first
        method, core = options.correction, (slice(None), slice(None))  # a whole grid's: every cell counts
        user = polygons_mask(options.stable_mask, grid) if options.stable_mask else None
        paper = MODES[method].paper_plane
        base = d_i if paper else 0.0
        res = apply_correction(s.filled - base, "none" if paper else method, grid, user_mask=user)
        offset = np.where(np.isfinite(s.filled), base + res.surface, np.nan)
        params, stable = {**res.params, "method": method}, res.stable_mask
    else:
        offset = np.where(np.isfinite(s.filled), given.offset, np.nan)
        params, stable, core = given.params, given.stable & np.isfinite(s.filled), given.core
    diff = s.filled - offset
    fill_sigma = np.where(s.own, s.own_sigma, refill_sigma(diff, s.filled_mask, stable, options))
    lod = detection_level(diff, stable, options.lod_confidence)
    z = z_value(options.lod_confidence)  # each cell's: the epochs' errors, the refill's
    se = (np.where(m, np.nan, cell_sigma(e.spread, e.counts)) for e, m in zip(epochs, (s.m_a, s.m_b), strict=True))
    lod_cell = np.maximum(cell_lod(lod, *se, z), z * fill_sigma)
    significant = patches(~s.filled_mask & (np.abs(np.nan_to_num(diff)) > lod_cell), MIN_CELLS)
    sides = refill_across_outline(diff, s.filled_mask & ~s.own, significant, options.fill_method)
    outline = np.nan_to_num(sides - diff)  # where the outline runs in the holes: a term
    return Corrected(
        offset, params, stable, given is not None, core, sides, sides + offset, fill_sigma, lod, lod_cell, outline
    )
