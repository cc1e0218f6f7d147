"""The volume step: five stages taking and returning frozen typed results, refill (:mod:`.refill`),
correction (:mod:`.correct`), classification (:func:`.nonsoil.classify`), interval (:mod:`.interval`) and
budgets (:func:`budgets`), gathered in a :class:`Volumes`."""

from __future__ import annotations

from functools import partial

import numpy as np

from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from . import coverage
from .change import budget, refilled_budget, signed_budget, thresholded_volumes
from .correct import Corrected, correct
from .holes.interpolate import fill
from .interval import Interval, interval
from .nonsoil import Areas, classify
from .refill import Refill, centred_heights, refill
from .results import Budgets, Cells, Epochs, Given, Grids, Volumes
from .zones import zone_budgets, zone_interval

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
    base = fill(base, gap & ~np.isfinite(h_a), options.fill_method)
    base = np.where(gap & np.isfinite(h_a), h_a - c.filled, base)
    grids = Grids(*s.heights, *layers, np.where(mask, base + c.filled, h_a), base)
    return Volumes(grids, *parts, c.params, iv.uncertainty, a.excluded, iv.blind)


def budgets(
    s: Refill, c: Corrected, a: Areas, iv: Interval, d_i, epochs: Epochs, grid: GridSpec, options: Options
) -> tuple[Budgets, Cells]:
    """Stage 5, the budgets: the headline's (the change areas) and those beside it, the zones', and the cells compared,
    each counted on a tile's core only; ``d_i``: the paper's plane offsets."""
    core, area = c.core, grid.cell_area
    d, filled, zones = c.diff[core], c.filled[core], []
    if options.zones:  # over the counted change, as the headline's, with intervals (whole grid; tiles: not yet)
        (rows, cols), whole = core, not c.tile
        zgrid = grid if whole else grid.window(rows.start, rows.stop, cols.start, cols.stop)
        interval = partial(zone_interval, iv.model, a.counted, iv.uncertainty) if whole else None
        counted = np.where(a.counted[core], d, np.where(np.isfinite(d), 0.0, np.nan))
        areas = (a.fill[core], a.cut[core])
        zones = zone_budgets(counted, zgrid, options.zones, whole=whole, interval=interval, areas=areas)
    out = Budgets(
        compensated=signed_budget(d, a.fill[core], a.cut[core], area),
        all_cells=budget(d, area),
        uncompensated=budget(filled, area),
        paper_plane=budget(filled - d_i[core], area),
        thresholded=thresholded_volumes(d, c.lod, area),
        holes=refilled_budget(d, s.filled_mask[core], area),
        zones=zones,
    )
    n_a, n_b = (e.counts for e in epochs)  # the empty cells (either survey, the before, the after), the coverage
    empty = (int((~np.isfinite(s.raw[core])).sum()), int((n_b[core] == 0).sum()), int((n_a[core] == 0).sum()))
    return out, Cells(*empty, coverage.counts(n_a, n_b, s.filled_mask, c.diff, core, edges=(not c.tile,) * 4))
