"""Stage 5, the budgets: the headline's (the change areas) and those beside it, the zones', and the
cells compared, each counted on a tile's core only."""

from __future__ import annotations

from functools import partial

import numpy as np

from ..core.types import GridSpec
from ..options import Options
from . import coverage
from .correct import Corrected
from .difference import budget, refilled_budget, signed_budget, thresholded_volumes
from .interval import Interval
from .nonsoil import Areas
from .refill import Refill
from .results import Budgets, Cells, Epochs
from .zones import zone_budgets, zone_interval


def budgets(
    s: Refill, c: Corrected, a: Areas, iv: Interval, d_i, epochs: Epochs, grid: GridSpec, options: Options
) -> tuple[Budgets, Cells]:
    """The budgets and the cells compared; ``d_i``: the paper's plane offsets."""
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
