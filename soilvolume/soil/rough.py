"""Rough cells: a canopy is a spread of heights a cell's slope does not explain (soil is smooth at a
cell's scale); used where no signal labelled any point, their volume carried in the interval."""

from __future__ import annotations

import numpy as np

ROUGH_FACTOR = 3.0  # residual spread over this many times the stable ground's is rough
ROUGH_MIN_M = 0.05
IQR_SPREAD = 1.5  # interquartile spread (IQR / 1.349) of a sloping cell over its standard deviation, with margin
MIN_POINTS = 6  # a spread of fewer points says little


def roughness(spread: np.ndarray, heights: np.ndarray, counts: np.ndarray, cell: float) -> np.ndarray:
    """Per-cell spread of heights (m) beyond a slope g's (|g| c / sqrt(12), times :data:`IQR_SPREAD`
    as an interquartile spread); NaN where too few points."""
    g2 = _steepest(heights, 1) ** 2 + _steepest(heights, 0) ** 2
    planar = IQR_SPREAD**2 * g2 / 12.0  # steps are per cell: g c
    with np.errstate(invalid="ignore"):
        r = np.sqrt(np.maximum(np.square(spread) - planar, 0.0))
    return np.where(counts >= MIN_POINTS, r, np.nan)


def _steepest(h: np.ndarray, axis: int) -> np.ndarray:
    """Per cell, the larger one-sided height step along ``axis`` (a central one halves a flank at a
    break of slope)."""
    before = np.abs(np.diff(h, axis=axis, prepend=np.nan))
    after = np.abs(np.diff(h, axis=axis, append=np.nan))
    return np.nan_to_num(np.fmax(before, after))


def rough_cells(r: np.ndarray, stable: np.ndarray) -> np.ndarray:
    """Cells whose spread ``r`` is over :data:`ROUGH_FACTOR` times stable ground's (>= :data:`ROUGH_MIN_M`)."""
    ref = r[stable & np.isfinite(r)]
    level = float(np.median(ref)) if ref.size else 0.0
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(r) > max(ROUGH_FACTOR * level, ROUGH_MIN_M)
