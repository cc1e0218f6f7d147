"""The volume step: five stages taking and returning frozen typed results, refill (:mod:`.refill`),
correction (:mod:`.correct`), classification (:func:`.nonsoil.classify`), interval (:mod:`.interval`) and
budgets (:mod:`.budgets`), gathered in a :class:`Volumes`."""

from __future__ import annotations

import numpy as np

from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from .budgets import budgets
from .correct import correct
from .holes.interpolate import fill
from .interval import interval
from .nonsoil import classify
from .refill import centred_heights, refill
from .results import Given, Grids, Volumes

__all__ = ["Given", "Volumes", "centred_heights", "compute_volumes"]


def compute_volumes(
    after: EpochDEM, before: EpochDEM, d_i, grid: GridSpec, options: Options, moved=None, given: Given | None = None
) -> Volumes:
    """The stages in turn; ``moved``: the move to a nearly as good pose, ``given``: a tiled run's window."""
    epochs = (after, before)
    s = refill(after, before, grid, options, given)
    c = correct(s, epochs, d_i, grid, options, given)
    a = classify(s, c, epochs, grid, options)
    iv = interval(s, c, a, epochs, grid, options, moved)
    parts = budgets(s, c, a, iv, d_i, epochs, grid, options)
    layers = (s.raw, c.filled, s.filled_mask, c.offset, c.diff, a.stable, a.counted, a.cut, a.classes)
    (h_a, h_b), mask = s.heights, s.filled_mask  # dem_after.tif, dem_before.tif: refilled cells get the before's
    base = np.where(mask, s.f_b, h_b)  # refilled height and it plus the refilled difference
    gap = mask & ~np.isfinite(base)
    if gap.any():
        base = fill(base, gap & ~np.isfinite(h_a), options.fill_method)
        base = np.where(gap & np.isfinite(h_a), h_a - c.filled, base)
    grids = Grids(*s.heights, *layers, np.where(mask, base + c.filled, h_a), base)
    return Volumes(grids, *parts, c.params, iv.uncertainty, a.excluded, iv.blind)
