"""The volume step of the method, on the two epochs' grids: a chain of five stages, each
taking and returning frozen typed results: refill (:mod:`.refill`), correction
(:mod:`.correct`), classification of the change and of what is not soil (:mod:`.classify`),
interval (:mod:`.interval`) and budgets (:mod:`.budgets`), gathered in a :class:`Volumes`."""

from __future__ import annotations

from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from .budgets import budgets
from .classify import Areas, classify
from .correct import Corrected, correct
from .interval import interval, pose_effect
from .refill import Refill, centred_heights, refill, refill_sigma, written_dems
from .results import Given, Grids, Volumes

__all__ = ["Given", "Volumes", "centred_heights", "compute_volumes", "pose_effect", "refill_sigma"]


def compute_volumes(
    after: EpochDEM, before: EpochDEM, d_i, grid: GridSpec, options: Options, moved=None, given: Given | None = None
) -> Volumes:
    """Raw difference; each epoch's weak cells refilled from its own neighbours; enclosed holes
    of the difference (empty in either epoch) filled from the surrounding difference, which is
    smooth on unchanged ground whatever the terrain -> correction -> change areas and what is
    not soil -> uncertainty -> budgets and zones. The epochs' per-cell height spreads give
    per-cell LoDs; ``moved``: the rigid move from the accepted pose to a nearly as good one
    (registration uncertainty); ``given``: the window of a tiled run (see :class:`Given`)."""
    epochs = (after, before)
    s = refill(after, before, grid, options, given)
    c = correct(s, epochs, d_i, grid, options, given)
    a = classify(s, c, epochs, grid, options)
    iv = interval(s, c, a, epochs, grid, options, moved)
    parts = budgets(s, c, a, iv, d_i, epochs, grid, options)
    ex = a.exclusion
    return Volumes(_grids(s, c, a, options.fill_method), *parts, c.params, iv.uncertainty, ex.report, iv.blind.report)


def _grids(s: Refill, c: Corrected, a: Areas, method: str) -> Grids:
    """The volume step's grids from its stages' results."""
    dem_out_a, dem_out_b = written_dems(s, c.filled, method)
    return Grids(
        dem_a=s.heights[0],
        dem_b=s.heights[1],
        raw=s.raw,
        filled=c.filled,
        filled_mask=s.filled_mask,
        offset=c.offset,
        diff=c.diff,
        stable=a.stable,
        change_mask=a.counted,
        cut_mask=a.cut,  # after the exclusions, as the headline sums it
        classes=a.exclusion.classes,
        dem_out_a=dem_out_a,
        dem_out_b=dem_out_b,
    )
