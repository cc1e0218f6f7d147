"""The volume step: five stages taking and returning frozen typed results, refill and
correction (:mod:`.refill`), classification (:func:`.nonsoil.classify`), interval (:func:`interval`: the error
model over the counted change (:mod:`.uncertainty`), the terms beyond it by name and the bound of what no survey saw
(:mod:`.holes.works`)) and budgets (:func:`budgets`), gathered in a :class:`Volumes`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..compensation.correction import MODES
from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from . import coverage
from .change import (
    broad_terms,
    budget,
    marginal_terms,
    refilled_budget,
    signed_budget,
    skirt_terms,
    thresholded_volumes,
)
from .holes.interpolate import fill
from .holes.works import blind_change, outline_sigma
from .nonsoil import Areas, classify
from .refill import Corrected, Refill, centred_heights, change_hole_sigma, correct, refill
from .results import Budgets, Cells, Epochs, Given, Grids, Volumes
from .uncertainty import interp_fraction, statistic_bias, volume_uncertainty
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


@dataclass(frozen=True)
class Interval:
    """report.json's ``uncertainty``, the error model (for the zones) and the holes no survey saw."""

    uncertainty: dict
    model: Callable[..., dict]
    blind: dict  # report.json's ``blind``: the holes no survey saw, their bound (m3 per part)


def interval(s: Refill, c: Corrected, a: Areas, epochs: Epochs, grid: GridSpec, options: Options, moved) -> Interval:
    """The interval of the counted change; a tile's registration and correction terms are left to the tiles'
    combination."""
    area, ex = grid.cell_area, a.excluded
    d, fa, ca = c.diff[c.core], a.fill[c.core], a.cut[c.core]  # areas decided with the halo, counted on the core
    parts = {"net": fa | ca, "cut": ca, "fill": fa}
    registration = signed_budget(pose_effect(s.f_a, grid, moved)[c.core], fa, ca, area)
    marginal = marginal_terms(d, fa, ca, c.lod_cell[c.core], area)
    skews = tuple(None if e.skew is None else e.skew[c.core] for e in epochs)
    statistic = statistic_bias(skews, s.filled_mask[c.core], parts, area)
    outline = outline_sigma(c.outline[c.core], d, parts, interp_fraction(s.filled_mask), area)
    reg_in = 0.0 if c.tile else 1.0
    skirt = skirt_terms(d, fa, ca, area)  # the areas' gentle edges under the detection level (a tile's: summed)
    broad = broad_terms(d, fa, ca, a.classes[c.core] == 0, grid.cell, c.lod)  # a settlement spread wide, on soil
    terms = (registration, marginal, ex["sigma_m3"], statistic, broad, *(() if c.tile else (skirt,)))
    extra = {k: float(np.linalg.norm([reg_in * registration[k], *(t[k] for t in terms[1:])])) for k in statistic}
    extra = {k: float(np.hypot(v, outline[k])) for k, v in extra.items()}
    hidden = blind_change(c.diff, epochs, a.counted, area, s.seen_once)
    levels = (c.params.get("strips") or {}).get("levels_m") or [0.0]
    span = max(levels) - min(levels)  # a cell given another strip's level, or a strip's edge off, is off by up to this
    strip_m3 = {k: float(m.sum()) * area * span for k, m in parts.items()}
    bound = {k: v + hidden["bound_m3"][k] + strip_m3[k] for k, v in ex["bound_m3"].items()}
    counted = np.zeros(c.diff.shape, bool)  # the error model over the cells counted: a tile's core
    counted[c.core] = True  # (the overview has the bias)
    n_coef = 0 if c.tile else MODES[options.correction].coefficients
    run = dict(grid=grid, confidence=options.lod_confidence, counted=counted, n_coef=n_coef, bound_m3=bound)
    tested = change_hole_sigma(c.diff, s.filled_mask, a.counted, c.lod_cell, options)
    model = partial(volume_uncertainty, c.diff, a.stable, fills=(s.filled_mask, s.own, c.fill_sigma, tested), **run)
    named = {"registration_m3": registration, "marginal_detections_m3": marginal, "classification_m3": terms[2]}
    named.update(statistic_m3=statistic, outline_m3=outline, skirt_m3=skirt, broad_m3=broad, strips_m3=strip_m3)
    unc = {**model(change_mask=a.counted, extra_sigma=extra), "lod_m": c.lod, **named}
    return Interval(unc, model, hidden)


def pose_effect(h_after: np.ndarray, grid: GridSpec, moved: np.ndarray | None) -> np.ndarray:
    """The difference's change (m) if the after surface moved by ``moved`` (4x4, local): -grad(H) . u horizontally."""
    if moved is None:
        return np.zeros(h_after.shape)
    x, y = grid.centers_local()
    p = np.stack([x, y, np.nan_to_num(h_after)], axis=-1)
    u = p @ moved[:3, :3].T + moved[:3, 3] - p
    gy, gx = np.gradient(h_after, grid.cell)  # rows run south: d/dy = -d/drow
    return -(gx * u[..., 0] - gy * u[..., 1])


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
    cov = coverage.counts(n_a, n_b, s.filled_mask, c.diff, epochs[0].all_points(), core, (not c.tile,) * 4)
    return out, Cells(*empty, cov)
