"""Stage 1, the refill: heights at the cell centres, each epoch's weak cells refilled from its own
neighbours, a survey's own holes where the other sees change across them (:mod:`.holes.works`),
and the enclosed holes of the difference from the difference around them. Stage 2, the correction (:func:`correct`):
the bias found on stable ground (a tile is given the overview's) subtracted, each cell's level of detection, holes
across the outline refilled (:mod:`.holes.works`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..compensation.correction import MODES
from ..compensation.correction import apply as apply_correction
from ..compensation.robust import nmad, patches
from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from .change import MIN_CELLS, cell_lod, cell_sigma
from .holes.interpolate import enclosed_holes, fill, patches_touching, refill_epoch, weak_cells
from .holes.testholes import error_by_radius, error_where
from .holes.works import fill_own_holes, refill_across_outline
from .results import Epochs, Given
from .uncertainty import detection_level, z_value
from .zones import polygons_mask

MIN_POINTS = 3  # a robust cell height needs at least this many points


@dataclass(frozen=True)
class Refill:
    """The refill's grids (m; masks bool), after first in each pair."""

    heights: tuple[np.ndarray, np.ndarray]  # the heights at the cell centres
    raw: np.ndarray  # their difference, NaN where either is empty
    f_a: np.ndarray  # the after heights refilled
    f_b: np.ndarray  # the before heights refilled
    m_a: np.ndarray  # the after survey's refilled weak cells
    m_b: np.ndarray  # the before survey's
    filled: np.ndarray  # the difference of the refilled heights, its enclosed holes filled
    filled_mask: np.ndarray  # every refilled cell with a value
    seen_once: np.ndarray  # a pile on a meadow: measured in one survey, may start a change area
    own: np.ndarray  # the cells filled in their own survey (holes/works)
    own_sigma: np.ndarray  # their one-sigma error (m)


def refill(after: EpochDEM, before: EpochDEM, grid: GridSpec, options: Options, given: Given | None) -> Refill:
    """The refill of the pair (see module); ``given``: the window of a tiled run."""
    med_a, med_b = (None, None) if given is None else given.median_counts
    n_a, n_b = after.counts, before.counts
    h_a, h_b = centred_heights(after, grid.cell, options, med_a), centred_heights(before, grid.cell, options, med_b)
    max_cells = int(options.fill_holes / grid.cell_area) if options.fill_holes > 0 else None
    method = options.fill_method
    weak = dict(ratio=options.min_count_ratio, min_points=MIN_POINTS, method=method)
    f_b, m_b = refill_epoch(h_b, n_b, **weak, median=med_b)
    f_a, m_a = refill_epoch(h_a, n_a, **weak, median=med_a)
    known = np.isfinite(f_a - f_b)
    hole = enclosed_holes(known, max_cells)
    # holes of one survey of any size are its own to fill where the other sees a pile across them
    own_holes = enclosed_holes(known, known.size) if max_cells else hole
    one = own_holes & ~hole & (np.isfinite(f_a) != np.isfinite(f_b))  # measured in one survey, beyond a hole
    sparse = m_a | weak_cells(n_a, 0.5, MIN_POINTS, med_a), m_b | weak_cells(n_b, 0.5, MIN_POINTS, med_b)
    f_a, f_b, own, own_sigma = fill_own_holes(f_a, f_b, own_holes, sparse, method, options.seed, grid.cell_area)
    filled = fill(f_a - f_b, hole & ~own, method)
    filled_mask = (m_a | m_b | hole | own) & np.isfinite(filled)
    return Refill((h_a, h_b), h_a - h_b, f_a, f_b, m_a, m_b, filled, filled_mask, one & own, own, own_sigma)


def centred_heights(dem: EpochDEM, cell: float, options: Options, median: float | None = None) -> np.ndarray:
    """The epoch's heights at its cell centres (:meth:`EpochDEM.centred`); its weak cells give no slope."""
    return dem.centred(cell, weak_cells(dem.counts, options.min_count_ratio, MIN_POINTS, median))


def refill_sigma(diff, filled_mask, stable, options: Options) -> np.ndarray:
    """Per-cell one-sigma error (m) of refilled cells: their patch's, on test holes of its radius in the stable
    difference."""
    if not filled_mask.any():
        return np.zeros(diff.shape)
    labels, n = scipy.ndimage.label(filled_mask, structure=scipy.ndimage.generate_binary_structure(2, 1))
    radius = np.sqrt(np.bincount(labels.ravel())[1:] / np.pi)
    per_patch = error_by_radius(diff, stable, options.fill_method, radius, options.seed)
    if per_patch is None:  # no room to measure it: one stable-ground noise level per cell
        s = nmad(diff[stable])
        return np.where(filled_mask, s if np.isfinite(s) else 0.0, 0.0)
    return np.where(filled_mask, np.r_[0.0, per_patch[:, 1]][labels], 0.0)


def change_hole_sigma(diff, filled_mask, counted, lod, options: Options) -> np.ndarray:
    """Per-cell one-sigma error (m) of the mean of each refilled patch in or along the counted change, on test holes of
    its radius centred in the change's deeper half over ``lod`` (a narrow trench's floor refills from its rim;
    :func:`.holes.testholes.error_where`); NaN elsewhere, and everywhere when no test hole fits."""
    out = np.full(diff.shape, np.nan)
    labels, n = scipy.ndimage.label(filled_mask, structure=scipy.ndimage.generate_binary_structure(2, 1))
    touching = patches_touching(labels, counted)
    if not touching.size:
        return out
    radius = np.sqrt(np.bincount(labels.ravel(), minlength=n + 1) / np.pi)
    measured = ~filled_mask & np.isfinite(diff)
    size = np.abs(np.nan_to_num(diff))
    deep = np.median(size[counted & measured]) if (counted & measured).any() else 0.0
    where = counted & measured & (size > lod) & (size >= deep)  # a survey misses the deeper half most
    per_patch = error_where(diff, measured, where, options.fill_method, radius[touching], options.seed)
    if per_patch is None:
        return out
    at = np.full(n + 1, np.nan)
    at[touching] = per_patch
    return np.where(labels > 0, at[labels], np.nan)


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
    soil = (epochs[0].nonsoil() == 0) & (epochs[1].nonsoil() == 0)  # a trench carried through a hole, not a crown
    sides = refill_across_outline(diff, s.filled_mask & ~s.own, significant, options.fill_method, soil)
    outline = np.nan_to_num(sides - diff)  # where the outline runs in the holes: a term
    return Corrected(
        offset, params, stable, given is not None, core, sides, sides + offset, fill_sigma, lod, lod_cell, outline
    )
