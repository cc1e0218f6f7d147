"""Slopes of a height grid per cell, for moving a cell's height from where its points lie to
its centre (:meth:`~.grid.EpochDEM.centred`)."""

from __future__ import annotations

import numpy as np

KINK_M = 0.1  # a change of slope this high over one cell is an edge (a bush, a rim), not noise


def slopes(h: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """dh/dx (east) and dh/dy (north) per cell: central differences where both neighbours have
    data, NaN where neither has. Where one has, the one-sided step, limited by the next step
    beyond it where the two differ by a kink (:func:`_limited`, minmod): a cell at a hole next to
    a bush, a vehicle or a rim otherwise takes the step onto it as its slope, and its points, all
    on that side, are moved by it (0.46 m on a 0.5 m cell beside a bush at a pit's rim,
    paper-veg20m-rgb); on a steady slope (a pit's wall, a pile's flank) the two steps agree."""
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
    """``step`` limited by ``beyond`` where the two differ by a kink of :data:`KINK_M` over a
    cell or more (see :func:`slopes`; kept where ``beyond`` is unknown, and where they differ by
    the heights' noise only: a sparse survey's edge cells keep the terrain's slope)."""
    with np.errstate(invalid="ignore"):
        agree = step * beyond > 0
        limited = np.where(agree, np.sign(step) * np.minimum(np.abs(step), np.abs(beyond)), 0.0)
        kink = np.abs(step - beyond) * cell > KINK_M
    return np.where(np.isfinite(beyond) & np.isfinite(step) & kink, limited, step)
