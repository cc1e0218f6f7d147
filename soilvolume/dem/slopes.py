"""Slopes of a height grid per cell, for moving a cell's height from where its points lie to
its centre (:meth:`~.grid.EpochDEM.centred`)."""

from __future__ import annotations

import numpy as np

KINK_M = 0.1  # a change of slope this high over one cell is an edge (a bush, a rim), not noise


def slopes(h: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """dh/dx (east) and dh/dy (north) per cell: central differences, else the one-sided step limited
    by the next one at a kink (:func:`_limited`; a cell at a hole beside a bush took the step onto it:
    0.46 m on a 0.5 m cell, paper-veg20m-rgb), NaN without neighbours."""
    out = []
    for axis in (1, 0):
        fwd = np.full(h.shape, np.nan)
        bwd = np.full(h.shape, np.nan)
        ahead = [slice(None)] * 2
        behind = [slice(None)] * 2
        ahead[axis], behind[axis] = slice(1, None), slice(None, -1)
        step = (h[tuple(ahead)] - h[tuple(behind)]) / cell
        fwd[tuple(behind)] = step
        bwd[tuple(ahead)] = step
        fwd2 = np.full(h.shape, np.nan)  # the step beyond the forward one, and behind the backward one
        bwd2 = np.full(h.shape, np.nan)
        fwd2[tuple(behind)] = fwd[tuple(ahead)]
        bwd2[tuple(ahead)] = bwd[tuple(behind)]
        both = np.isfinite(fwd) & np.isfinite(bwd)
        one = np.where(np.isfinite(fwd), _limited(fwd, fwd2, cell), _limited(bwd, bwd2, cell))
        out.append(np.where(both, 0.5 * (fwd + bwd), one))
    return out[0], -out[1]  # rows run south


def _limited(step: np.ndarray, beyond: np.ndarray, cell: float) -> np.ndarray:
    """``step`` limited by ``beyond`` (minmod) where they differ by :data:`KINK_M` or more over a cell;
    kept elsewhere (noise only: a sparse survey's edge cells keep the terrain's slope)."""
    with np.errstate(invalid="ignore"):
        agree = step * beyond > 0
        limited = np.where(agree, np.sign(step) * np.minimum(np.abs(step), np.abs(beyond)), 0.0)
        kink = np.abs(step - beyond) * cell > KINK_M
    return np.where(np.isfinite(beyond) & np.isfinite(step) & kink, limited, step)
