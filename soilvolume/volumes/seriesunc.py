"""The interval of a period of a series (:mod:`.series`).

With ``Z_k = T_k + e_k`` and ``D_k = Z_k - Z_0``, a period's difference ``D_j - D_i`` holds only
its two epochs' errors: ``var(V_ij) = var(E_i) + var(E_j)``, consecutive periods covary by
``-var(E_i)`` (so their sum is not the root-sum-square of their intervals) and the cumulative
``D_n`` holds E0's and the last epoch's only. Each interval is thus computed on its own difference,
whose stable residuals are ``e_j - e_i``, with one correction surface fitted from E0 (and the
cumulative), two between later epochs; its registration term is ``pose_j - pose_i`` per cell.
"""

from __future__ import annotations

import numpy as np

from ..compensation.correction import MODES
from ..core.types import GridSpec
from ..options import Options
from .difference import signed_budget
from .holes.interpolate import typical_radius
from .interval import marginal_terms
from .refill import refill_sigma
from .uncertainty import interp_fraction, statistic_bias, volume_uncertainty


def period_uncertainty(
    diff: np.ndarray,
    areas: tuple[np.ndarray, np.ndarray],
    works: np.ndarray,
    stable: np.ndarray,
    refilled: np.ndarray,
    lod_cell: np.ndarray,
    pose: np.ndarray,
    skews: tuple,
    grid: GridSpec,
    options: Options,
    fits: int,
) -> dict:
    """± half-widths (m3) of a period's net (over ``works``), cut and fill (its ``areas``: fill, cut)
    from its ``diff`` (see module); ``pose``: the difference's change at the alternative poses (m),
    ``skews``: (end, start) cell statistics' (:func:`.uncertainty.statistic_bias`), ``fits``: surfaces."""
    (fill_area, cut_area), area = areas, grid.cell_area
    reg_v = signed_budget(pose, fill_area, cut_area, area)
    reg_v["net"] = abs(float(np.nansum(np.where(works, pose, 0.0)))) * area
    marginal = marginal_terms(diff, fill_area, cut_area, lod_cell, area)
    stat = statistic_bias(skews, refilled, {"net": works, "cut": cut_area, "fill": fill_area}, area)
    extra = {k: float(np.linalg.norm([reg_v[k], marginal[k], stat[k]])) for k in ("net", "cut", "fill")}
    coef = MODES[options.correction].coefficients
    common = dict(
        n_coef=coef * fits,
        filled_mask=refilled,
        fill_sigma=refill_sigma(diff, refilled, stable, options),
        interp_fraction=interp_fraction(typical_radius(refilled)),
        extra_sigma=extra,
        surface=coef > 0,
    )
    conf = options.lod_confidence
    on_works = volume_uncertainty(diff, stable, works, grid, conf, **common)
    on_areas = volume_uncertainty(diff, stable, fill_area | cut_area, grid, conf, **common)
    named = {"registration_m3": {k: reg_v[k] for k in ("net", "cut", "fill")}, "statistic_m3": stat}
    return _merged(on_works, on_areas, conf, {**named, "marginal_detections_m3": marginal, "correction_fits": fits})


def _merged(on_works: dict, on_areas: dict, conf: float, named: dict) -> dict:
    """A period's interval: the net's from the works, cut and fill from its own areas, the
    ``named`` terms."""
    by = {"net": on_works, "cut": on_areas, "fill": on_areas}
    kept = ("sigma_m", "lod_m", "nugget_m2", "psill_m2", "range_m", "bias_sigma_m", "stable_cells")
    return {
        **{k: u[k] for k, u in by.items()},
        "confidence": conf,
        **{k: on_works[k] for k in kept},
        **named,
        "terms_m3": {k: u["terms_m3"][k] for k, u in by.items()},  # one-sigma, in the order of uncertainty.TERMS
    }
