"""Level of detection and volume uncertainty from the stable-ground residuals.

* LoD (GCD-style): ``z * sigma`` per cell, sigma = NMAD of the stable residuals, optionally
  combined in quadrature with a per-cell standard error.
* Volume uncertainty with spatially correlated error (:mod:`.variogram`), the refills', the
  correction's leftover bias and what a caller adds, at a confidence.
"""

from __future__ import annotations

from statistics import NormalDist
from typing import Any

import numpy as np
import scipy

from ..compensation.robust import nmad
from ..compensation.stable import noise_sigma
from ..core.types import GridSpec
from .variogram import bias_sigma, fit_spherical, region_sigma, semivariogram

INTERP_FRACTION = 0.15


def interp_fraction(patch_radius_cells: float) -> float:
    """One-sigma error of refilled change volume, as a share of it (fully correlated): refills over
    change edges overshoot convex toes and rims, and the partly covered cells around a hole bias
    it; both sit at the patch's rim, so the share falls as 1 / radius in cells (measured: 30-80 %
    on holes of about 2 cells, under 5 % on holes of 6 cells)."""
    return float(min(0.5, max(INTERP_FRACTION, 1.0 / max(patch_radius_cells, 1.0))))


def z_value(confidence: float = 0.95) -> float:
    """Two-sided normal quantile (1.96 for 95 %)."""
    return NormalDist().inv_cdf(0.5 + confidence / 2)


#: the one-sigma terms (m^3) of ``terms_m3[part]``, in their order: the area's error model, the
#: refilled share of change, the refill error, the leftover bias, extras (what a caller adds)
TERMS = ("area_model", "refilled_share", "refill_error", "leftover_bias", "extras")


def volume_uncertainty(
    diff_corrected: np.ndarray,
    stable_mask: np.ndarray,
    change_mask: np.ndarray | None,
    grid: GridSpec,
    confidence: float = 0.95,
    *,
    n_coef: int = 6,
    filled_mask: np.ndarray | None = None,
    own_fill: np.ndarray | None = None,  # see filled_mask
    interp_fraction: float = INTERP_FRACTION,
    fill_sigma: np.ndarray | None = None,
    extra_sigma: dict[str, float] | None = None,
    counted: np.ndarray | None = None,
    surface: bool = True,
    bound_m3: dict[str, float] | None = None,
) -> dict[str, Any]:
    """+- half-widths (m^3) at ``confidence`` of the net/cut/fill summed over ``change_mask``
    (all valid cells when None; cut/fill by the sign of the difference) and ``net_compared_area``
    over every valid cell, with the error model's figures (lod_m, sigma_m, the variogram and its
    model, areas, ``terms_m3`` per part in the order of :data:`TERMS`). ``n_coef``: coefficients
    of the correction surface (6 surface, 3 plane, 1 constant, 0 none); the refills and
    ``surface``: see :class:`_PartTerms`; ``extra_sigma``: further one-sigma terms (m^3) per part;
    ``counted``: the cells the volumes sum over (a tile's core), while the error model uses every
    stable cell; ``bound_m3``: volume per part that may or may not be soil, added as it is (:func:`widen`)."""
    d, valid = diff_corrected, np.isfinite(diff_corrected)
    stable = stable_mask & valid
    if counted is not None:
        valid = valid & counted
    region = valid if change_mask is None else change_mask & valid
    vario = semivariogram(d, stable, grid.cell)
    model = fit_spherical(*vario)
    b = bias_sigma(int(stable.sum()), grid.cell, model, n_coef) if n_coef else 0.0
    parts = {"net": region, "cut": region & (d < 0), "fill": region & (d > 0), "net_compared_area": valid}
    pt = _PartTerms(d, valid, stable, grid, filled_mask, own_fill, fill_sigma, interp_fraction, surface)
    extra = extra_sigma or {}
    area_model = {k: region_sigma(int(m.sum()), grid.cell, model, b) for k, m in parts.items()}
    terms = {k: pt.terms(m, area_model[k], extra.get(k, 0.0)) for k, m in parts.items()}
    out: dict[str, Any] = widen({k: z_value(confidence) * float(np.linalg.norm(t)) for k, t in terms.items()}, bound_m3)
    sigma = nmad(d[stable]) if stable.any() else float("nan")
    out.update(confidence=confidence, sigma_m=sigma, lod_m=_lod(d[stable], sigma, confidence))
    out.update(nugget_m2=model["nugget"], psill_m2=model["psill"], range_m=model["range"], bias_sigma_m=b)
    out.update(pt.described(region, parts, stable, grid.cell_area))
    out.update(
        unclassified_m3={k: float((bound_m3 or {}).get(k, 0.0)) for k in ("net", "cut", "fill")},
        terms_m3=terms,  # one-sigma: area model, refilled share, refill error, leftover bias, extras
        variogram={"lag_m": vario[0].tolist(), "gamma_m2": vario[1].tolist(), "pairs": vario[2].tolist()},
    )
    return out


def widen(half: dict[str, float], bound: dict[str, float] | None) -> dict[str, float]:
    """Half-widths (m3) widened by what the classification could not attribute (``bound``, m3
    per part): the truth lies anywhere between counting all of it and none, so it adds as it is
    (the net's half-width over every compared cell too)."""
    b = bound or {}
    out = {k: v + float(b.get(k, 0.0)) for k, v in half.items()}
    if "net_compared_area" in out:
        out["net_compared_area"] = half["net_compared_area"] + float(b.get("net", 0.0))
    return out


class _PartTerms:
    """The one-sigma terms (m^3) of a part beyond its area's error model: the refilled share of
    its change (``interp``), the refill error (``refill``) and the correction's leftover bias
    (``unmodelled``). ``filled_mask``: interpolated cells; their volume gets a fully correlated
    error of ``fraction`` x its absolute value (hole fills over change edges were off by 10-22 %
    of their volume on synthetic pairs), and ``fill_sigma`` (m, per cell: the error of refilling
    known ground) summed fully correlated within each connected refilled patch; ``own``: the
    refilled cells filled in their own survey (volumes/holes/epochfill), ``fill_sigma`` only.
    ``surface``: a correction surface was fitted (its leftover's spread on stable ground is
    carried over the part's area, fully correlated)."""

    def __init__(
        self, diff, valid, stable, grid: GridSpec, filled_mask, own, fill_sigma, fraction: float, surface: bool
    ):
        self.cell_area, self.fraction = grid.cell_area, fraction
        self.filled = np.zeros(valid.shape, bool) if filled_mask is None else filled_mask & valid
        self.shared = self.filled if own is None else self.filled & ~own  # interpolated in the difference
        self.absd = np.abs(np.where(valid, diff, 0.0))
        self.labels, self.n_patches = scipy.ndimage.label(self.filled)
        self.fs = np.zeros(valid.shape) if fill_sigma is None else np.where(self.filled, fill_sigma, 0.0)
        self.leftover = leftover_bias(diff, stable, grid.cell)
        # the correction surface's residual systematic error where it cannot be seen: the spread of
        # its leftover over the stable ground, carried fully correlated over the part's area
        seen = self.leftover[stable & np.isfinite(self.leftover)] if surface else np.empty(0)  # no surface, none
        self.residual = float(np.sqrt(np.mean(np.square(seen)))) if seen.size else 0.0

    def described(self, region: np.ndarray, parts: dict, stable: np.ndarray, cell_area: float) -> dict:
        """The report's totals of the terms over ``region`` and the areas (stable, change, parts)."""
        return {
            "interpolated_m3": self.interp(region) / max(self.fraction, 1e-12),
            "refill_sigma_m3": self.refill(region),
            "unmodelled_bias_m3": self.unmodelled(region),
            "correction_residual_m3": self.residual * float(region.sum()) * cell_area,
            "stable_cells": int(stable.sum()),
            "change_area_m2": float(region.sum()) * cell_area,
            "part_area_m2": {k: float(m.sum()) * cell_area for k, m in parts.items()},
        }

    def terms(self, m: np.ndarray, area_model: float, extras: float) -> list[float]:
        """The one-sigma terms of the part ``m``, in the order of :data:`TERMS`."""
        return [area_model, self.interp(m), self.refill(m), self.unmodelled(m), extras]

    def interp(self, m: np.ndarray) -> float:
        return self.fraction * float(self.absd[m & self.shared].sum()) * self.cell_area

    def refill(self, m: np.ndarray) -> float:
        labels, n = self.labels, self.n_patches
        per_patch = scipy.ndimage.sum(np.where(m, self.fs, 0.0), labels, np.arange(1, n + 1)) * self.cell_area
        return float(np.sqrt(np.sum(np.square(per_patch)))) if n else 0.0

    def unmodelled(self, m: np.ndarray) -> float:  # fully correlated over the part
        signed = abs(float(np.nansum(np.where(m, self.leftover, 0.0)))) * self.cell_area
        return float(np.hypot(signed, self.residual * float(m.sum()) * self.cell_area))


def statistic_bias(skews: tuple, refilled: np.ndarray, parts: dict[str, np.ndarray], cell_area: float) -> dict:
    """One-sigma volume (m3) per part of the cell statistic's own bias where outliers, walls or
    canopy leftovers fall in cells: how far the statistic moved each epoch's cells from their
    medians, differenced, summed over the part (fully correlated: a wall or a rim biases all its
    cells alike). ``skews``: (after, before) per-cell height minus median (None: 0); refilled
    cells carry no statistic of their own."""
    d = np.zeros(refilled.shape)
    for sign, sk in zip((1.0, -1.0), skews, strict=True):
        if sk is not None:
            d += sign * np.nan_to_num(sk)
    d[refilled] = 0.0
    return {k: abs(float(d[m].sum())) * cell_area for k, m in parts.items()}


def detection_level(diff: np.ndarray, stable: np.ndarray, confidence: float = 0.95) -> float:
    """Level of detection (m) of one cell: from the stable-ground residuals (see :func:`_lod`),
    but at most twice the LoD of the neighbour-difference noise, so real change left in what
    was taken as stable ground (e.g. a thin layer on well georeferenced surveys) cannot inflate it."""
    r = diff[stable & np.isfinite(diff)]
    lod = _lod(r, nmad(r), confidence) if r.size else None
    noise = noise_sigma(diff)
    cap = 2.0 * z_value(confidence) * noise if np.isfinite(noise) else None
    known = [v for v in (lod, cap) if v is not None and np.isfinite(v)]
    return float(min(known)) if known else 0.0


def leftover_bias(residual: np.ndarray, stable: np.ndarray, cell: float, scale_m: float = 10.0) -> np.ndarray:
    """The bias the correction surface left, carried into the change areas: the stable-ground
    residuals smoothed over ``scale_m`` (normalized convolution; NaN far from stable ground). A
    dome that is not quite a degree-2 surface leaves millimetres here that a volume multiplies."""
    w = (stable & np.isfinite(residual)).astype(float)
    s = max(1.0, scale_m / cell)
    num = scipy.ndimage.gaussian_filter(np.where(w > 0, residual, 0.0), s)
    den = scipy.ndimage.gaussian_filter(w, s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.05, num / den, np.nan)


def _lod(stable_residuals: np.ndarray, sigma: float, confidence: float) -> float | None:
    """LoD at ``confidence``: z x NMAD, or the empirical quantile of |stable residuals| when the
    residuals have heavier tails than a normal distribution (they usually do)."""
    if not np.isfinite(sigma):
        return None
    r = np.abs(stable_residuals[np.isfinite(stable_residuals)])
    empirical = float(np.quantile(r, confidence)) if r.size >= 20 else 0.0
    return max(z_value(confidence) * sigma, empirical)
