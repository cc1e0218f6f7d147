"""The volume step of the method, on the two epochs' grids: the difference, each epoch's weak
cells refilled, holes filled, the bias correction (:mod:`soilvolume.compensation`), change areas,
budgets, uncertainty and zones."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np
from scipy import ndimage

from ..compensation.correction import MODES
from ..compensation.correction import apply as apply_correction
from ..compensation.robust import patches
from ..core.types import GridSpec
from ..dem import holes, testholes
from ..dem.grid import EpochDEM
from ..options import Options
from . import coverage
from .blind import blind_change
from .change import MIN_CELLS
from .difference import budget, difference, signed_budget
from .epochfill import fill_own_holes
from .nonsoil import Exclusion, exclude_nonsoil
from .outline import refill_across_outline

MIN_POINTS = 3  # a robust cell height needs at least this many points
MAX_TEST_RADIUS = 32.0  # cells: the largest test hole of the refill error


@dataclass(frozen=True)
class Volumes:
    """The volume step's result: grids on the shared grid (m) and budgets (m3, as report.json
    holds them: net, cut, fill, cells, area_m2)."""

    dem_a: np.ndarray  # H_after the difference is taken from: heights at the cell centres (local)
    dem_b: np.ndarray  # H_before, the same
    raw: np.ndarray  # H_after - H_before, NaN where either epoch is empty
    filled: np.ndarray  # the same with weak cells and enclosed holes refilled
    filled_mask: np.ndarray  # the refilled cells
    offset: np.ndarray  # the correction subtracted (d_i and/or the stable-ground surface)
    diff: np.ndarray  # the corrected difference: filled - offset
    stable: np.ndarray  # the stable cells of the error model
    params: dict  # the correction's parameters
    uncertainty: dict  # volume uncertainty, LoD, registration and marginal-detection terms
    change_mask: np.ndarray  # the areas of significant change
    compensated: dict  # the headline budget: fill and cut over the change areas
    all_cells: dict  # every compared cell
    uncompensated: dict  # the refilled difference without correction
    paper_plane: dict  # the paper's H_after - H_before - d_i over every compared cell
    change_areas: dict  # = compensated
    thresholded: dict  # cells above the LoD only
    holes: dict  # refilled area and volume
    empty_cells: int
    empty_before: int
    empty_after: int
    zones: list = field(default_factory=list)  # per-polygon budgets (--zones)
    excluded: dict = field(default_factory=dict)  # what is not soil: classes, objects (volumes/nonsoil)
    blind: dict = field(default_factory=dict)  # holes without any point in the works (volumes/blind)
    dem_out_a: np.ndarray | None = None  # dem_after.tif: dem_a, the refilled heights on filled_mask (local)
    dem_out_b: np.ndarray | None = None  # dem_before.tif: the same; dem_out_a - dem_out_b - offset = diff
    classes: np.ndarray | None = None  # excluded.tif: the class of each cell (volumes/nonsoil.CLASS_CODES)
    cut_mask: np.ndarray | None = None  # the cut areas of change_mask (the rest of it is fill)
    coverage: dict = field(default_factory=dict)  # the after footprint's cells compared (volumes/coverage)


@dataclass(frozen=True)
class Given:
    """What a tile of a grid too large for one process takes from the whole grid instead of
    finding it in its own window: the correction surface and stable ground (from an overview
    of the grid), each epoch's median point count (weak cells), and the window's core (the
    cells it counts; the rest is halo, context only)."""

    offset: np.ndarray  # the correction surface on the window (m)
    stable: np.ndarray  # stable ground on the window
    params: dict  # the correction's parameters
    median_counts: tuple[float, float]  # (after, before)
    core: tuple[slice, slice]


def compute_volumes(
    after: EpochDEM, before: EpochDEM, d_i, grid: GridSpec, options: Options, moved=None, given: Given | None = None
) -> Volumes:
    """Raw difference; each epoch's weak cells refilled from its own neighbours; enclosed holes
    of the difference (empty in either epoch) filled from the surrounding difference, which is
    smooth on unchanged ground whatever the terrain -> correction -> change areas, budgets,
    uncertainty, zones. The epochs' per-cell height spreads give per-cell LoDs; ``moved``: the
    rigid move from the accepted pose to a nearly as good one (registration uncertainty);
    ``given``: the window of a tiled run (see :class:`Given`)."""
    from .change import change_areas
    from .uncertainty import detection_level

    s = _refilled(after, before, grid, options, given)
    filled_mask = s["filled_mask"]
    if given is None:
        offset, params, stable, _ = correction(s["filled"], d_i, grid, options)
        core = (slice(None), slice(None))  # the cells the budgets count: all
    else:
        offset = np.where(np.isfinite(s["filled"]), given.offset, np.nan)
        params, stable = given.params, given.stable & np.isfinite(s["filled"])
        core = given.core  # the halo is context only
    diff = s["filled"] - offset
    fill_sigma = np.where(s["own"], s["own_sigma"], refill_sigma(diff, filled_mask, stable, options))
    lod = detection_level(diff, stable, options.lod_confidence)
    lod_cell = _cell_lods(after, before, s, lod, fill_sigma, options.lod_confidence)
    significant = patches(~filled_mask & (np.abs(np.nan_to_num(diff)) > lod_cell), MIN_CELLS)
    sides = refill_across_outline(diff, filled_mask & ~s["own"], significant, options.fill_method)
    outline, diff = np.nan_to_num(sides - diff), sides  # where the outline runs in the holes: a term
    filled = diff + offset
    fill_area, cut_area = change_areas(diff, lod_cell, refilled=filled_mask & ~s["seen_once"])
    change = fill_area | cut_area
    ex = _exclude(diff, (fill_area, cut_area), (after, before), offset, grid, options, s, stable)
    fill_area, cut_area = ex.fill, ex.cut
    # stable ground for the error model: never a cell of (or next to) a detected change area,
    # unless the user drew it
    quiet = stable & ~ndimage.binary_dilation(change, iterations=max(1, round(2.0 / grid.cell)))
    if not options.stable_mask and quiet.sum() >= 12:
        stable = quiet
    d, fa, ca = diff[core], fill_area[core], cut_area[core]  # areas decided with the halo, counted on the core
    terms = _extra_terms((after, before), s["f_a"], filled_mask, grid, moved, given, core, (d, fa, ca), lod_cell, ex)
    terms["extra"] = _with_outline(terms, outline[core], d, filled_mask, (fa, ca), grid.cell_area)
    counted = fill_area | cut_area  # the change areas without moved objects
    hidden = blind_change(diff, (after, before), counted, grid.cell_area, s["seen_once"])
    bound = {k: ex.bound[k] + hidden.bound[k] for k in ex.bound}  # unclassified, and unseen
    model = _error_model(diff, stable, grid, options, given, core, filled_mask, s["own"], fill_sigma, bound)
    unc = model(change_mask=counted, extra_sigma=terms.pop("extra"))
    headline = signed_budget(d, fa, ca, grid.cell_area)
    vols = {
        "dem_a": s["heights"][0],
        "dem_b": s["heights"][1],
        **written_dems(s, filled, filled_mask, options.fill_method),
        "raw": s["raw"],
        "filled": filled,
        "filled_mask": filled_mask,
        "offset": offset,
        "diff": diff,
        "stable": stable,
        "params": params,
        "uncertainty": {
            **unc,
            "lod_m": lod,
            "registration_m3": terms["registration_m3"],
            "marginal_detections_m3": terms["marginal_detections_m3"],
            "classification_m3": ex.sigma,
            "statistic_m3": terms["statistic_m3"],
            "outline_m3": terms["outline_m3"],
        },
        "change_mask": counted,
        "cut_mask": cut_area,  # after the exclusions, as the headline sums it
        "excluded": ex.report,
        "blind": hidden.report,
        "classes": ex.classes,
        "compensated": headline,
        "change_areas": headline,
        **_budgets(s, filled, diff, d_i, core, lod, grid.cell_area, given is None, (after.counts, before.counts)),
    }
    if options.zones:
        vols["zones"] = _zones(d, counted, (fa, ca), grid, options, given, core, model, unc)
    return Volumes(**vols)


def _exclude(diff, areas, epochs, offset, grid: GridSpec, options: Options, s: dict, stable) -> Exclusion:
    """What is not soil (:func:`.nonsoil.exclude_nonsoil`) with the run's options."""
    mode, heights, refilled = options.exclude, s["heights"], s["filled_mask"] & ~s["seen_once"]
    return exclude_nonsoil(diff, *areas, epochs, offset, grid, mode, heights, stable, refilled, objects=options.objects)


def _refilled(after: EpochDEM, before: EpochDEM, grid: GridSpec, options: Options, given: Given | None) -> dict:
    """The heights at the cell centres (``heights``: after, before), the raw difference, each
    epoch's weak cells refilled (``f_a``, ``m_a``, ``m_b``), enclosed holes filled (``filled``)
    and the refilled cells (``filled_mask``)."""
    med_a, med_b = (None, None) if given is None else given.median_counts
    n_a, n_b = after.counts, before.counts
    h_a, h_b = centred_heights(after, grid.cell, options, med_a), centred_heights(before, grid.cell, options, med_b)
    raw = difference(h_a, h_b)
    max_cells = int(options.fill_holes / grid.cell_area) if options.fill_holes > 0 else None
    weak = dict(ratio=options.min_count_ratio, min_points=MIN_POINTS, method=options.fill_method)
    f_b, m_b = holes.refill_epoch(h_b, n_b, **weak, median=med_b)
    f_a, m_a = holes.refill_epoch(h_a, n_a, **weak, median=med_a)
    known = np.isfinite(difference(f_a, f_b))
    hole = holes.enclosed_holes(known, max_cells)
    # holes of one survey of any size are its own to fill where the other sees a pile across them
    own_holes = holes.enclosed_holes(known, known.size) if max_cells else hole
    one = own_holes & ~hole & (np.isfinite(f_a) != np.isfinite(f_b))  # measured in one survey, beyond a hole
    f_a, f_b, own, own_sigma = fill_own_holes(
        f_a, f_b, own_holes, _sparse(m_a, m_b, n_a, n_b, given), options.fill_method, options.seed, grid.cell_area
    )
    filled = difference(f_a, f_b)
    filled = holes.fill(filled, hole & ~own, options.fill_method)
    filled_mask = (m_a | m_b | hole | own) & np.isfinite(filled)
    return dict(
        heights=(h_a, h_b),
        raw=raw,
        f_a=f_a,
        f_b=f_b,
        m_a=m_a,
        m_b=m_b,
        filled=filled,
        filled_mask=filled_mask,
        seen_once=one & own,  # a pile on a meadow: measured in the after survey, may start a change area
        own=own,
        own_sigma=own_sigma,
    )


def written_dems(s: dict, filled: np.ndarray, mask: np.ndarray, method: str) -> dict:
    """The DEMs written beside difference.tif: the heights at the cell centres, and on the refilled
    cells (``mask``) the before survey's refilled height (its own refill, else interpolated from
    its neighbours, else the after height less the difference) and that height plus the refilled
    difference ``filled``: dem_after - dem_before - correction gives difference.tif back."""
    h_a, h_b = s["heights"]
    base = np.where(mask, s["f_b"], h_b)
    gap = mask & ~np.isfinite(base)
    if gap.any():
        base = holes.fill(base, gap & ~np.isfinite(h_a), method)
        base = np.where(gap & np.isfinite(h_a), h_a - filled, base)
    return {"dem_out_a": np.where(mask, base + filled, h_a), "dem_out_b": base}


def _sparse(m_a, m_b, n_a, n_b, given: Given | None) -> tuple[np.ndarray, np.ndarray]:
    """Each epoch's cells a hole's rim cannot trust: refilled, or under half the median count
    (partly covered beside a hole)."""
    med_a, med_b = (None, None) if given is None else given.median_counts
    return m_a | holes.weak_cells(n_a, 0.5, MIN_POINTS, med_a), m_b | holes.weak_cells(n_b, 0.5, MIN_POINTS, med_b)


def _cell_lods(after: EpochDEM, before: EpochDEM, s: dict, lod: float, fill_sigma, confidence: float) -> np.ndarray:
    """Each cell's level of detection: the stable ground's, the epochs' own height errors, the
    refill error of refilled cells."""
    from .change import cell_lod, cell_sigma
    from .uncertainty import z_value

    z = z_value(confidence)
    se_a = np.where(s["m_a"], np.nan, cell_sigma(after.spread, after.counts))
    se_b = np.where(s["m_b"], np.nan, cell_sigma(before.spread, before.counts))
    return np.maximum(cell_lod(lod, se_a, se_b, z), z * fill_sigma)


def _extra_terms(epochs, f_a, filled_mask, grid: GridSpec, moved, given, core, counted, lod_cell, ex) -> dict:
    """The one-sigma terms (m3 per part) beyond the error model: the registration's (the pose's
    effect on the counted ``(d, fill, cut)``), the marginal detections, the cell statistic's
    bias, and all of them with the classification's (``extra``)."""
    from .change import marginal_volume
    from .uncertainty import statistic_bias

    d, fa, ca = counted
    area = grid.cell_area
    reg_v = signed_budget(pose_effect(f_a, grid, moved)[core], fa, ca, area)
    marginal = {
        "fill": marginal_volume(d, fa, lod_cell[core], area),
        "cut": marginal_volume(d, ca, lod_cell[core], area),
    }
    marginal["net"] = float(np.hypot(marginal["fill"], marginal["cut"]))
    reg_in = 0.0 if given else 1.0  # a tile: the pose is common to all tiles, summed across them
    skews = tuple(None if e.skew is None else e.skew[core] for e in epochs)
    stat = statistic_bias(skews, filled_mask[core], {"net": fa | ca, "cut": ca, "fill": fa}, area)
    extra = {k: float(np.linalg.norm([reg_in * reg_v[k], marginal[k], ex.sigma[k], stat[k]])) for k in stat}
    return {"registration_m3": reg_v, "marginal_detections_m3": marginal, "statistic_m3": stat, "extra": extra}


def _with_outline(terms: dict, delta: np.ndarray, d, filled_mask, areas, area: float) -> dict:
    """The extra terms with where the outline runs inside the holes refilled across it
    (:func:`~.outline.outline_sigma`, kept in ``terms`` as ``outline_m3``)."""
    from .outline import outline_sigma
    from .uncertainty import interp_fraction

    fa, ca = areas
    share = interp_fraction(holes.typical_radius(filled_mask))
    terms["outline_m3"] = outline_sigma(delta, d, {"net": fa | ca, "cut": ca, "fill": fa}, share, area)
    return {k: float(np.hypot(v, terms["outline_m3"][k])) for k, v in terms["extra"].items()}


def _error_model(diff, stable, grid: GridSpec, options: Options, given, core, filled_mask, own, fill_sigma, bound):
    """The error model (:func:`~.uncertainty.volume_uncertainty` with the run's arguments) over
    the cells a caller gives: the headline's change areas, a zone's."""
    from .uncertainty import interp_fraction, volume_uncertainty

    return partial(
        volume_uncertainty,
        diff,
        stable,
        grid=grid,
        confidence=options.lod_confidence,
        n_coef=0 if given else MODES[options.correction].coefficients,  # a tile: the overview has the bias
        filled_mask=filled_mask,
        own_fill=own,
        fill_sigma=fill_sigma,
        interp_fraction=interp_fraction(holes.typical_radius(filled_mask & ~own)),
        counted=None if given is None else _mask(diff.shape, core),
        surface=given is None and MODES[options.correction].coefficients > 0,  # a tile: see n_coef
        bound_m3=bound,
    )


def _budgets(s: dict, filled, diff, d_i, core, lod: float, area: float, whole: bool, counts) -> dict:
    """The budgets beside the headline (every compared cell, uncompensated, the paper's plane,
    thresholded, refilled), the empty cells and the coverage, counted on the ``core``."""
    from .uncertainty import thresholded_volumes

    d, (n_a, n_b) = diff[core], counts
    return {
        "all_cells": budget(d, area),
        "uncompensated": budget(filled[core], area),
        "paper_plane": budget(filled[core] - d_i[core], area),
        "thresholded": thresholded_volumes(d, lod, area),
        "holes": holes.summary(d, s["filled_mask"][core], area),
        "empty_cells": int((~np.isfinite(s["raw"][core])).sum()),
        "empty_before": int((n_b[core] == 0).sum()),
        "empty_after": int((n_a[core] == 0).sum()),
        "coverage": coverage.counts(n_a, n_b, s["filled_mask"], diff, core, edges=(whole,) * 4),
    }


def _zones(d, counted, areas, grid: GridSpec, options: Options, given, core, model, unc) -> list:
    """The zones' budgets over the counted change cells, fill and cut over the (fill, cut)
    ``areas`` as the headline's, with their intervals (whole grid only)."""
    from .zones import zone_budgets, zone_interval

    rows, cols = core
    zgrid = grid if given is None else grid.window(rows.start, rows.stop, cols.start, cols.stop)
    interval = None if given is not None else partial(zone_interval, model, counted, unc)  # tiles: not yet
    return zone_budgets(
        np.where(counted[core], d, np.where(np.isfinite(d), 0.0, np.nan)),
        zgrid,
        options.zones,
        whole=given is None,
        interval=interval,
        areas=areas,
    )


def centred_heights(dem: EpochDEM, cell: float, options: Options, median: float | None = None) -> np.ndarray:
    """The epoch's heights at its cell centres (:meth:`EpochDEM.centred`); its weak cells (see
    :func:`holes.weak_cells`, ``median``: the whole grid's median count for a tile) give no slope."""
    return dem.centred(cell, holes.weak_cells(dem.counts, options.min_count_ratio, MIN_POINTS, median))


def _mask(shape: tuple[int, int], core: tuple[slice, slice]) -> np.ndarray:
    """True on the ``core`` window of a grid of ``shape``."""
    out = np.zeros(shape, bool)
    out[core] = True
    return out


def pose_effect(h_after: np.ndarray, grid: GridSpec, moved: np.ndarray | None) -> np.ndarray:
    """Change of the difference (m per cell) if the after surface moved horizontally by ``moved``
    (4x4, local): -grad(H) . u; its vertical part and tilt are absorbed by the bias correction."""
    if moved is None:
        return np.zeros(h_after.shape)
    x, y = grid.centers_local()
    p = np.stack([x, y, np.nan_to_num(h_after)], axis=-1)
    u = p @ moved[:3, :3].T + moved[:3, 3] - p
    gy, gx = np.gradient(h_after, grid.cell)  # rows run south: d/dy = -d/drow
    return -(gx * u[..., 0] - gy * u[..., 1])


def refill_sigma(diff, filled_mask, stable, options: Options) -> np.ndarray:
    """Per-cell one-sigma error (m) of refilled cells: the error of a hole's mean height grows with
    its size, so each refilled patch gets the error measured by refilling known stable cells of the
    difference with test holes of about its radius (radii 1, 2, 4, ... cells up to the largest
    patch's, at most ``MAX_TEST_RADIUS``: weak cells spread over a grid finer than the points form
    one giant "hole"; interpolated in log radius; the largest measured radius for patches too large
    for the stable ground). 0 where nothing was refilled."""
    if not filled_mask.any():
        return np.zeros(diff.shape)
    labels, n = ndimage.label(filled_mask, structure=ndimage.generate_binary_structure(2, 1))
    radius = np.sqrt(np.bincount(labels.ravel())[1:] / np.pi)
    ladder = 2.0 ** np.arange(int(np.log2(min(max(radius.max(), 1.0), MAX_TEST_RADIUS))) + 1)
    measured = [(r, testholes.fill_error(diff, stable, options.fill_method, r, seed=options.seed)) for r in ladder]
    measured = [(r, s) for r, s in measured if np.isfinite(s)]
    if not measured:  # no room to measure it: one stable-ground noise level per cell
        from ..compensation.robust import nmad

        s = nmad(diff[stable])
        return np.where(filled_mask, s if np.isfinite(s) else 0.0, 0.0)
    r_m, s_m = np.log(np.array(measured)).T
    per_patch = np.exp(np.interp(np.log(np.maximum(radius, 1.0)), r_m, s_m))
    return np.where(filled_mask, np.r_[0.0, per_patch][labels], 0.0)


def correction(diff, d_i, grid: GridSpec, options: Options):
    """(correction surface to subtract, its parameters, stable-cell mask, change mask).

    Stable ground is found the same way for every method, so residual statistics and the
    uncertainty are comparable; ``paper-plane`` subtracts the paper's ``d_i`` first."""
    method = options.correction
    paper = MODES[method].paper_plane
    base = d_i if paper else 0.0
    user_mask = None
    if options.stable_mask:
        from .zones import polygons_mask

        user_mask = polygons_mask(options.stable_mask, grid)
    res = apply_correction(diff - base, "none" if paper else method, grid, user_mask=user_mask)
    offset = np.where(np.isfinite(diff), base + res.surface, np.nan)
    return offset, {**res.params, "method": method}, res.stable_mask, res.change_mask
