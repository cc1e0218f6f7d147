"""Change areas, cut and fill apart: patches of a few cells beyond their own level of detection
(the stable LoD, raised where a cell's heights are uncertain; border cells, partly covered, never
start one), each with a buffer of neighbours whatever their sign, which recovers the toes of piles
and rims of pits (a buffer of one sign would select noise by its sign and bias cut and fill). The budgets of the
paper's ``V = S_g * sum(H_after - H_before - d_i)``: fill (added, >= 0), cut (removed, >= 0), net = fill - cut."""

from __future__ import annotations

import numpy as np
import scipy

from ..compensation.robust import patches
from ..core.cells import block_sums

MIN_CELLS = 3  # a change area has at least this many significant cells
BUFFER_CELLS = 1  # cells of buffer around each change area
MARGINAL_CELLS = 50  # smaller areas barely above their LoD may be noise (a few correlation areas)
_EIGHT = np.ones((3, 3), bool)
SKIRT_CELLS = 3  # the ring around the change areas whose same-signed change they may leave out
BLOCK_M = 5.0  # blocks of about this side whose mean change is compared with the other blocks'
BROAD_Z = 3.0  # a block stands out at this many times the blocks' NMAD (3: one noise block in 370)


def cell_sigma(spread: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Standard error (m) of each cell's height: spread / sqrt(points) (NaN where empty)."""
    return np.where(counts > 0, spread / np.sqrt(np.maximum(counts, 1)), np.nan)


def cell_lod(lod: float, se_a: np.ndarray, se_b: np.ndarray, z: float) -> np.ndarray:
    """Per-cell LoD: the stable one, or ``z`` standard errors of the difference if larger (NaN: 0)."""
    se = np.sqrt(np.nan_to_num(se_a) ** 2 + np.nan_to_num(se_b) ** 2)
    return np.maximum(lod, z * se)


def change_areas(
    diff: np.ndarray, lod: np.ndarray | float, *, refilled: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(fill, cut) masks (see module); a buffer cell both reach is neither's. ``refilled`` cells start none; a refilled
    patch joins a touching area of its sign no smaller (1.4 m3 of a 69 m3 pit's cut otherwise: paper-veg20m-rgb)."""
    valid = np.isfinite(diff)
    d = np.where(valid, diff, 0.0)
    lod = np.broadcast_to(lod, d.shape)
    measured = scipy.ndimage.binary_erosion(valid, border_value=0)  # border cells are partly covered
    if refilled is not None:
        measured &= ~refilled
    fill_core, cut_core = patches(measured & (d > lod), MIN_CELLS), patches(measured & (d < -lod), MIN_CELLS)
    fill, cut = (
        scipy.ndimage.binary_dilation(m, _EIGHT, iterations=BUFFER_CELLS) & valid for m in (fill_core, cut_core)
    )
    both = fill & cut
    fill, cut = (fill & ~both) | fill_core, (cut & ~both) | cut_core
    if refilled is None or not refilled.any():
        return fill, cut
    labels, n = scipy.ndimage.label(refilled & valid & ~fill & ~cut, structure=_EIGHT)  # the refilled patches
    idx = np.arange(1, n + 1)
    vol = scipy.ndimage.sum(d, labels, idx)
    rim = scipy.ndimage.grey_dilation(labels, footprint=_EIGHT) * (labels == 0)  # each patch's ring of known cells
    out = []
    for area, sign in ((fill, 1.0), (cut, -1.0)):
        comp, k = scipy.ndimage.label(area, structure=_EIGHT)  # per cell of the area, its volume of that sign
        volume = np.r_[0.0, np.maximum(sign * scipy.ndimage.sum(d, comp, np.arange(1, k + 1)), 0.0)][comp]
        works = scipy.ndimage.maximum(volume, rim, idx)
        out.append(area | np.r_[False, (sign * vol > 0) & (works >= sign * vol)][labels])
    return out[0], out[1]


def marginal_terms(diff: np.ndarray, fill: np.ndarray, cut: np.ndarray, lod, cell_area: float) -> dict:
    """Per part, the volume (m3) of areas under ``MARGINAL_CELLS`` cells whose mean |difference| is under twice their
    LoD (noise could make them); the net's in quadrature."""
    d, out = np.where(np.isfinite(diff), diff, 0.0), {}
    for key, area in (("fill", fill), ("cut", cut)):
        labels, n = scipy.ndimage.label(area, structure=_EIGHT)
        idx = np.arange(1, n + 1)
        mean_abs = scipy.ndimage.mean(np.abs(d), labels, idx)
        mean_lod = scipy.ndimage.mean(np.broadcast_to(lod, d.shape), labels, idx)
        vol = np.abs(scipy.ndimage.sum(d, labels, idx)) * cell_area
        size = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        out[key] = float(vol[(mean_abs < 2.0 * mean_lod) & (size < MARGINAL_CELLS)].sum())
    out["net"] = float(np.hypot(out["fill"], out["cut"]))
    return out


def skirt_terms(diff: np.ndarray, fill: np.ndarray, cut: np.ndarray, cell_area: float) -> dict:
    """Per part, the change (m3) in the :data:`SKIRT_CELLS` cells around its areas that the areas leave out: the
    difference summed there when it carries the part's sign (a lowering's or a pile's gentle edge under the detection
    level; noise sums to about nothing); the net's, the size of their difference."""
    d, out = np.where(np.isfinite(diff), diff, 0.0), {}
    changed = fill | cut
    for key, area, sign in (("fill", fill, 1.0), ("cut", cut, -1.0)):
        ring = scipy.ndimage.binary_dilation(area, _EIGHT, iterations=SKIRT_CELLS) & ~changed if area.any() else area
        out[key] = max(0.0, sign * float(d[ring].sum()) * cell_area)
    out["net"] = abs(out["fill"] - out["cut"])
    return out


def broad_terms(diff: np.ndarray, fill: np.ndarray, cut: np.ndarray, soil: np.ndarray, cell: float, lod: float) -> dict:
    """Per part, the change (m3) in blocks of about :data:`BLOCK_M` away from the areas and their skirts whose mean
    stands out of the blocks' spread (:data:`BROAD_Z` x their NMAD) and reaches half the cells' ``lod`` (m), on
    ``soil`` cells (nothing left out as not soil): a settlement or a thin layer spread wide under each cell's
    detection level (averaged over a block, it is not); the net's, the size of their difference."""
    quiet = np.isfinite(diff) & soil & ~scipy.ndimage.binary_dilation(fill | cut, _EIGHT, iterations=SKIRT_CELLS)
    b = max(3, round(BLOCK_M / cell))
    sums, counts = block_sums(np.where(quiet, diff, 0.0), b), block_sums(quiet, b)
    full = counts >= 0.5 * b * b
    out = {"fill": 0.0, "cut": 0.0}
    if full.sum() >= 8:
        means = sums[full] / counts[full]
        spread = 1.4826 * float(np.median(np.abs(means - np.median(means))))
        for key, sign in (("fill", 1.0), ("cut", -1.0)):
            over = sign * means > max(BROAD_Z * spread, 0.5 * lod)
            out[key] = max(0.0, float(sign * sums[full][over].sum())) * cell * cell
    out["net"] = abs(out["fill"] - out["cut"])
    return out


def fill_cut(d: np.ndarray, cell_area: float) -> dict[str, float]:
    """Net, cut and fill (m3) of the finite differences ``d``."""
    fill, cut = float(d[d > 0].sum()) * cell_area, float(-d[d < 0].sum()) * cell_area
    return {"net": fill - cut, "cut": cut, "fill": fill}


def part_budget(d: np.ndarray, cells: np.ndarray, cell_area: float) -> dict:
    """Net, cut, fill (m3) and area (m2) of ``d`` over ``cells`` (NaN as 0)."""
    return {**fill_cut(np.where(cells, np.nan_to_num(d), 0.0), cell_area), "area_m2": float(cells.sum()) * cell_area}


def budget(diff: np.ndarray, cell_area: float, mask: np.ndarray | None = None) -> dict[str, float]:
    """Cut, fill and net (m3) over the finite cells of ``diff`` (and ``mask`` when given)."""
    ok = np.isfinite(diff) if mask is None else np.isfinite(diff) & mask
    out = fill_cut(diff[ok], cell_area)  # + 0.0: no -0.0 cut
    return {**out, "cut": out["cut"] + 0.0, "cells": int(ok.sum()), "area_m2": float(ok.sum() * cell_area)}


def signed_budget(diff: np.ndarray, fill_area: np.ndarray, cut_area: np.ndarray, cell_area: float) -> dict:
    """Fill over the fill areas, cut over the cut areas (m3), net = fill - cut."""
    fill = float(np.nansum(np.where(fill_area, diff, 0.0)) * cell_area)
    cut = float(-np.nansum(np.where(cut_area, diff, 0.0)) * cell_area) + 0.0
    cells = int((fill_area | cut_area).sum())
    return {"net": fill - cut, "cut": cut, "fill": fill, "cells": cells, "area_m2": cells * cell_area}


def refilled_budget(diff: np.ndarray, filled_mask: np.ndarray, cell_area: float) -> dict:
    """The refilled cells' count, area and net volume."""
    d = np.where(filled_mask, diff, 0.0)
    n = int(filled_mask.sum())
    return {"filled_cells": n, "filled_area_m2": n * cell_area, "filled_net_m3": float(np.nansum(d) * cell_area)}


def thresholded_volumes(
    diff: np.ndarray, lod: float | np.ndarray, cell_area: float, min_cells: int = 1
) -> dict[str, float]:
    """Net, cut, fill (m^3) over cells with |d| >= ``lod``, without same-sign patches under ``min_cells`` (isolated
    noise)."""
    keep = np.isfinite(diff) & (np.abs(diff) >= lod)
    if min_cells > 1:
        keep = patches(keep & (diff > 0), min_cells) | patches(keep & (diff < 0), min_cells)
    return {**fill_cut(np.where(keep, diff, 0.0), cell_area), "area_m2": float(keep.sum() * cell_area)}
