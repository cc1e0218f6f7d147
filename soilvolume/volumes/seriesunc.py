"""The interval of a period of a series of surveys (see :mod:`.series`).

Covariance. Write epoch k's corrected surface as ``Z_k = T_k + e_k`` (truth plus error; E0
defines the frame, so its registration error is nil, not its height error). Each later epoch
is corrected once, relative to E0: ``D_k = Z_k - Z_0``, so the period difference is
``D_j - D_i = (T_j - T_i) + (e_j - e_i)``: E0's error cancels from every period that does not
start at E0, and a period's error holds only the errors of its own two epochs. Hence

- ``var(V_ij) = var(E_i) + var(E_j)`` (volumes ``E_k`` of ``e_k`` over the period's cells);
- ``cov(V_hi, V_ij) = -var(E_i)``: two consecutive periods share epoch i's error with opposite
  signs (a survey that reads high makes the period before it too large and the one after it too
  small), so the sum of the periods is not the root-sum-square of their intervals;
- the cumulative ``D_n - D_0 = D_n`` holds E0's and the last epoch's errors only, whatever
  happened between: the intermediate errors cancel in the telescoping sum.

Each interval is therefore computed on its own difference ``D_j - D_i``, whose stable-ground
residuals are exactly ``e_j - e_i`` there: the error model of
:func:`.uncertainty.volume_uncertainty` (variogram, refills, leftover bias) sees the two epochs'
combined error, never a third epoch's. The fitted correction surfaces: one for a period from E0
and for the cumulative (E0 is not corrected), two (each later epoch's own, independent) for a
period between two later epochs. The registration term is the change of the period's volume
when both epochs' poses move to their nearly as good alternatives (``pose_j - pose_i``, per
cell, so the shared epoch's pose enters its two periods with opposite signs as well).
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
    """± half-widths (m3, at ``options.lod_confidence``) of a period's net (summed over
    ``works``), cut and fill (over its own ``areas``: fill, cut), from its difference ``diff``
    (see the module's covariance). ``pose``: per-cell change of the difference (m) when the two
    epochs' poses move to their alternatives; ``skews``: the two epochs' (end, start) cell statistics'
    offsets from their medians (:func:`.uncertainty.statistic_bias`); ``fits``: correction
    surfaces in the difference."""
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
    return {
        "net": on_works["net"],
        "cut": on_areas["cut"],
        "fill": on_areas["fill"],
        "confidence": conf,
        "sigma_m": on_works["sigma_m"],
        "lod_m": on_works["lod_m"],
        **{k: on_works[k] for k in ("nugget_m2", "psill_m2", "range_m", "bias_sigma_m", "stable_cells")},
        **named,
        "terms_m3": {  # one-sigma: area model, refilled share, refill error, leftover bias, extras
            "net": on_works["terms_m3"]["net"],
            "cut": on_areas["terms_m3"]["cut"],
            "fill": on_areas["terms_m3"]["fill"],
        },
    }
