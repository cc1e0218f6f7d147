"""Volumes of a series E0 ... En on one grid, built so that the periods add up: the volume step of
each pair E0 -> Ek gives ``D_k`` (``D_0 = 0``) on the cells every pair compares, refilled in any,
stable in all. A period i -> j is ``D_j - D_i``; its net is summed over the works (every period's
change areas), so the nets telescope to ``W_n``; cut and fill are its own change areas,
``below_detection`` the rest of the net.

The intervals: with ``Z_k = T_k + e_k`` and ``D_k = Z_k - Z_0``, a period's difference holds only
its two epochs' errors: ``var(V_ij) = var(E_i) + var(E_j)``, consecutive periods covary by
``-var(E_i)`` (so their sum is not the root-sum-square of their intervals) and the cumulative
``D_n`` holds E0's and the last epoch's only. Each interval is thus computed on its own difference,
whose stable residuals are ``e_j - e_i``, with one correction surface fitted from E0 (and the
cumulative), two between later epochs; its registration term is ``pose_j - pose_i`` per cell."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..compensation.correction import MODES
from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from .change import cell_lod, cell_sigma, change_areas, marginal_terms, signed_budget
from .compute import pose_effect
from .refill import refill_sigma
from .results import Volumes
from .uncertainty import detection_level, statistic_bias, volume_uncertainty, z_value


@dataclass(frozen=True)
class Change:
    """One period (or the cumulative) ``start`` -> ``end``: difference (m), change areas, budgets, interval (m3)."""

    start: int
    end: int
    diff: np.ndarray
    fill_area: np.ndarray
    cut_area: np.ndarray
    volume: dict  # net (over the works), cut, fill (own areas), below_detection
    uncertainty: dict


@dataclass(frozen=True)
class SeriesVolumes:
    """The series' grids and changes: ``to_e0[k]`` = D_k (NaN outside ``valid``)."""

    to_e0: list[np.ndarray]
    valid: np.ndarray
    refilled: np.ndarray
    stable: np.ndarray
    works: np.ndarray
    periods: list[Change]
    cumulative: Change


def combine(
    vols: list[Volumes], dems: list[EpochDEM], moves: list[np.ndarray | None], grid: GridSpec, options: Options
) -> SeriesVolumes:
    """The series from the pairs E0 -> Ek (``vols[k-1]``), the DEMs (E0 first), the moves to alternative poses."""
    valid = np.logical_and.reduce([np.isfinite(v.diff) for v in vols])
    refilled = np.logical_or.reduce([v.filled_mask for v in vols]) & valid
    stable = np.logical_and.reduce([v.stable for v in vols]) & valid & ~refilled
    to_e0 = [np.where(valid, 0.0, np.nan)] + [np.where(valid, v.diff, np.nan) for v in vols]
    se = [np.where(refilled, np.nan, cell_sigma(d.spread, d.counts)) for d in dems]
    pose = [np.zeros(valid.shape), *(pose_effect(v.dem_a, grid, m) for v, m in zip(vols, moves, strict=True))]
    n = len(to_e0) - 1
    pairs = [(i, i + 1) for i in range(n)] + [(0, n)]
    found = {}
    for i, j in pairs:
        diff = to_e0[j] - to_e0[i]
        conf = options.lod_confidence
        lod_cell = cell_lod(detection_level(diff, stable, conf), se[i], se[j], z_value(conf))
        found[i, j] = (diff, change_areas(diff, lod_cell, refilled=refilled), lod_cell)
    works = np.logical_or.reduce([fill | cut for _, (fill, cut), _ in found.values()]) & valid
    works_m3 = [math.fsum(d[works].tolist()) * grid.cell_area for d in to_e0]  # W_k: D_k summed over the works
    run = (works, stable, refilled, grid, options)
    skews = [d.skew for d in dems]
    changes = [_period(i, j, *found[i, j], works_m3, pose[j] - pose[i], (skews[j], skews[i]), run) for i, j in pairs]
    return SeriesVolumes(to_e0, valid, refilled, stable, works, changes[:-1], changes[-1])


def _period(i: int, j: int, diff, areas: tuple, lod_cell, works_m3: list, pose, skews: tuple, run: tuple) -> Change:
    """The period ``i`` -> ``j``: its budgets, the ± (m3) of its net over the works, of cut and fill over its
    ``areas``; ``pose``, ``skews``: see module."""
    (fill_area, cut_area), (works, stable, refilled, grid, options) = areas, run
    area, fits = grid.cell_area, 1 if i == 0 else 2  # E0 is never corrected (see module)
    b = signed_budget(diff, fill_area, cut_area, area)
    net = works_m3[j] - works_m3[i]
    volume = {"net": net, "cut": b["cut"], "fill": b["fill"], "below_detection": net - (b["fill"] - b["cut"])}
    reg_v = signed_budget(pose, fill_area, cut_area, area)
    reg_v["net"] = abs(float(np.nansum(np.where(works, pose, 0.0)))) * area
    marginal = marginal_terms(diff, fill_area, cut_area, lod_cell, area)
    stat = statistic_bias(skews, refilled, {"net": works, "cut": cut_area, "fill": fill_area}, area)
    extra = {k: float(np.linalg.norm([reg_v[k], marginal[k], stat[k]])) for k in ("net", "cut", "fill")}
    coef, conf = MODES[options.correction].coefficients, options.lod_confidence
    common = dict(n_coef=coef * fits, fills=(refilled, None, refill_sigma(diff, refilled, stable, options)))
    on_works = volume_uncertainty(diff, stable, works, grid, conf, **common, extra_sigma=extra)
    on_areas = volume_uncertainty(diff, stable, fill_area | cut_area, grid, conf, **common, extra_sigma=extra)
    by = {"net": on_works, "cut": on_areas, "fill": on_areas}  # the net's from the works, cut and fill their areas
    kept = ("sigma_m", "lod_m", "nugget_m2", "psill_m2", "range_m", "bias_sigma_m", "stable_cells")
    unc = {
        **{k: u[k] for k, u in by.items()},
        "confidence": conf,
        **{k: on_works[k] for k in kept},
        "registration_m3": {k: reg_v[k] for k in ("net", "cut", "fill")},
        "statistic_m3": stat,
        "marginal_detections_m3": marginal,
        "correction_fits": fits,
        "terms_m3": {k: u["terms_m3"][k] for k, u in by.items()},  # one-sigma, in the order of uncertainty.TERMS
    }
    return Change(i, j, diff, fill_area, cut_area, volume, unc)
