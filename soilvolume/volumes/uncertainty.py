"""Level of detection and volume uncertainty from the stable-ground residuals.

* LoD (GCD-style): ``z * sigma`` per cell, sigma = NMAD of the stable residuals, optionally
  combined in quadrature with a per-cell standard error.
* Volume uncertainty with spatially correlated error (Rolstad et al. 2009; Anderson 2019): an
  empirical semivariogram of the stable residuals (exact, from grid shifts) fitted by a spherical
  model ``nugget + psill * sph(h, range)``; a volume over ``n`` cells of area ``A`` then has
  variance ``n * nugget * cell^4`` (uncorrelated) ``+ A^2 * psill * f(A, range)`` (correlated),
  plus the error of the correction surface's level estimated on the stable ground.
"""

from __future__ import annotations

import math
from statistics import NormalDist
from typing import Any

import numpy as np
from scipy import ndimage

from ..compensation.robust import nmad, patches
from ..core.types import GridSpec

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


def semivariogram(
    residual: np.ndarray,
    mask: np.ndarray,
    cell: float,
    n_lags: int = 24,
    max_lag_cells: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Isotropic empirical semivariogram from row/column shifts of the masked residuals:
    (lags_m, gamma_m2, n_pairs) for roughly log-spaced lags up to half the masked extent."""
    z = np.where(mask & np.isfinite(residual), residual, np.nan)
    rr, cc = np.nonzero(np.isfinite(z))
    if rr.size < 2:
        return np.empty(0), np.empty(0), np.empty(0, int)
    extent = max(np.ptp(rr), np.ptp(cc)) + 1
    top = max(1, min(max_lag_cells or extent // 2, extent - 1))
    lags = np.unique(np.round(np.geomspace(1, top, n_lags)).astype(int))
    out_l, out_g, out_n = [], [], []
    for h in lags:
        d = np.concatenate([(z[:, h:] - z[:, :-h]).ravel(), (z[h:] - z[:-h]).ravel()])
        d = d[np.isfinite(d)]
        if d.size >= 10:
            out_l.append(h * cell)
            out_g.append(0.5 * float(np.mean(d * d)))
            out_n.append(d.size)
    return np.array(out_l), np.array(out_g), np.array(out_n)


def spherical(h: np.ndarray, nugget: float, psill: float, rng: float) -> np.ndarray:
    """Spherical semivariogram model with a nugget (gamma(0+) = nugget)."""
    s = np.minimum(np.asarray(h, float) / rng, 1.0)
    return nugget + psill * (1.5 * s - 0.5 * s**3)


RANGE_GRID = 192  # ranges tried in each round of the fit's range search
RANGE_ROUNDS = 4  # rounds, each on the bracket of the round before's best range (~1e-7 relative)


def fit_spherical(lags: np.ndarray, gamma: np.ndarray, n_pairs: np.ndarray) -> dict[str, float]:
    """Weighted least-squares spherical fit (weights: the pairs behind each lag): {nugget, psill,
    range} (m^2, m^2, m), nugget and psill within [0, 2 max(gamma)], the range within
    [lags[0] / 2, 2 lags[-1]]. For a given range the model is linear in nugget and psill, solved
    exactly (:func:`_best_levels`); the range is searched on a log grid refined around its best
    point, so the fit is the global least-squares one, not a local optimum from a start."""
    if lags.size < 3:
        g = float(gamma.mean()) if gamma.size else 0.0
        return {"nugget": g, "psill": 0.0, "range": float(lags.max()) if lags.size else 0.0}
    w, cap = np.asarray(n_pairs, float), 2.0 * float(gamma.max())
    lo, hi = math.log(float(lags[0]) * 0.5), math.log(float(lags[-1]) * 2.0)
    for _ in range(RANGE_ROUNDS):
        logs = np.linspace(lo, hi, RANGE_GRID)
        cost, levels = _best_levels(lags, gamma, w, np.exp(logs), cap)
        i = int(np.argmin(cost))
        lo, hi = logs[max(i - 1, 0)], logs[min(i + 1, RANGE_GRID - 1)]
    return {"nugget": float(levels[0, i]), "psill": float(levels[1, i]), "range": float(np.exp(logs[i]))}


def _best_levels(
    lags: np.ndarray, gamma: np.ndarray, w: np.ndarray, ranges: np.ndarray, cap: float
) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``ranges``: the weighted least-squares cost of the spherical model and its
    (nugget, psill) within [0, ``cap``] (a convex problem in two unknowns: the unconstrained
    solution when it is inside the box, else the best one on the box's edges), as (R,), (2, R)."""
    s = np.minimum(lags[None, :] / ranges[:, None], 1.0)
    b = 1.5 * s - 0.5 * s**3  # (R, L): the model's shape at each lag
    sw, sg, sb, sbb, sgb = w.sum(), w @ gamma, b @ w, (b * b) @ w, b @ (w * gamma)
    det = sw * sbb - sb * sb
    with np.errstate(invalid="ignore", divide="ignore"):
        a, c = (sbb * sg - sb * sgb) / det, (sw * sgb - sb * sg) / det  # unconstrained
        edges = [
            (np.zeros_like(sb), sgb / sbb),  # no nugget
            (np.full_like(sb, cap), (sgb - cap * sb) / sbb),  # nugget at its bound
            (np.full_like(sb, sg / sw), np.zeros_like(sb)),  # no sill
            ((sg - cap * sb) / sw, np.full_like(sb, cap)),  # sill at its bound
        ]
    inside = (det > 0) & (a >= 0) & (a <= cap) & (c >= 0) & (c <= cap)
    candidates = [(np.where(inside, a, 0.0), np.where(inside, c, 0.0), inside)]
    candidates += [(*(np.clip(np.nan_to_num(v), 0.0, cap) for v in edge), True) for edge in edges]
    cost, levels = np.full(len(ranges), np.inf), np.zeros((2, len(ranges)))
    for nugget, psill, ok in candidates:
        r = gamma[None, :] - nugget[:, None] - psill[:, None] * b
        here = np.where(ok, (r * r) @ w, np.inf)
        better = here < cost
        cost = np.where(better, here, cost)
        levels = np.where(better, np.stack([nugget, psill]), levels)
    return cost, levels


def correlated_fraction(area: float, rng: float) -> float:
    """Rolstad et al. (2009): variance of the mean of a spherically correlated field over a
    disc-equivalent area, as a fraction of the point variance."""
    if area <= 0:
        return 0.0
    if rng <= 0:
        return 0.0
    radius = math.sqrt(area / math.pi)
    if radius >= rng:
        return math.pi * rng * rng / (5 * area)
    q = radius / rng
    return 1 - q + q**3 / 5


def region_sigma(
    n_cells: int, cell: float, model: dict[str, float], bias_sigma: float = 0.0, per_cell_var: float = 0.0
) -> float:
    """One-sigma volume uncertainty (m^3) over ``n_cells`` cells."""
    if n_cells <= 0:
        return 0.0
    area = n_cells * cell * cell
    var_unc = n_cells * (model["nugget"] + per_cell_var) * cell**4
    var_cor = area * area * model["psill"] * correlated_fraction(area, model["range"])
    var_sys = (area * bias_sigma) ** 2
    return math.sqrt(var_unc + var_cor + var_sys)


def bias_sigma(n_stable: int, cell: float, model: dict[str, float], n_coef: int) -> float:
    """One-sigma error of the correction surface's level at a change cell: the mean error over
    the stable ground, inflated by the number of fitted coefficients."""
    if n_stable <= 0:
        return 0.0
    area = n_stable * cell * cell
    var_mean = model["nugget"] / n_stable + model["psill"] * correlated_fraction(area, model["range"])
    return math.sqrt(max(n_coef, 1) * var_mean)


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
    per_cell_sigma: np.ndarray | None = None,
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
    (all valid cells when None), cut/fill split by the sign of the corrected difference, and
    ``net_compared_area`` for a sum over every valid cell (e.g. thresholded or raw volumes).
    ``n_coef`` = coefficients of the correction surface (6 surface, 3 plane, 1 constant, 0 none).
    ``filled_mask``: interpolated cells; their volume gets a further, fully correlated one-sigma
    error of ``interp_fraction`` x its absolute value (hole fills over change edges were off by
    10-22 % of their volume on synthetic pairs), and ``fill_sigma`` (m, per cell: the error of
    refilling known ground) summed fully correlated within each connected refilled patch.
    ``own_fill``: refilled cells filled in their own survey (volumes/epochfill): ``fill_sigma`` only.
    ``extra_sigma``: further one-sigma terms (m^3) per part (net, cut, fill), e.g. the volume the
    change detection picks up from noise on stable ground.
    ``counted``: the cells the volumes sum over (a tile's core; default all), while the error
    model uses every stable cell. ``surface``: a correction surface was fitted (its leftover's
    spread on stable ground is carried over the part's area, fully correlated). ``bound_m3``:
    volume per part that may or may not be soil (no signal could say): added to the half-width
    as it is, a bound rather than a random error (see :func:`widen`).
    Also returns lod_m, sigma_m (NMAD), nugget_m2, psill_m2,
    range_m, the variogram, areas."""
    valid = np.isfinite(diff_corrected)
    stable = stable_mask & valid
    if counted is not None:
        valid = valid & counted
    region = valid if change_mask is None else change_mask & valid
    sigma = nmad(diff_corrected[stable]) if stable.any() else float("nan")
    lags, gamma, npairs = semivariogram(diff_corrected, stable, grid.cell)
    model = fit_spherical(lags, gamma, npairs)
    z = z_value(confidence)
    pcv = 0.0 if per_cell_sigma is None else float(np.nanmean(np.square(per_cell_sigma[region])))
    b = bias_sigma(int(stable.sum()), grid.cell, model, n_coef) if n_coef else 0.0
    parts = {
        "net": region,
        "cut": region & (diff_corrected < 0),
        "fill": region & (diff_corrected > 0),
        "net_compared_area": valid,
    }
    extra = extra_sigma or {}
    pt = _PartTerms(diff_corrected, valid, stable, grid, filled_mask, own_fill, fill_sigma, interp_fraction, surface)
    terms = {
        k: pt.terms(m, region_sigma(int(m.sum()), grid.cell, model, b, pcv), extra.get(k, 0.0))
        for k, m in parts.items()
    }
    out: dict[str, Any] = widen({k: z * float(np.linalg.norm(t)) for k, t in terms.items()}, bound_m3)
    out.update(
        confidence=confidence,
        sigma_m=sigma,
        lod_m=_lod(diff_corrected[stable], sigma, confidence),
        nugget_m2=model["nugget"],
        psill_m2=model["psill"],
        range_m=model["range"],
        bias_sigma_m=b,
        interpolated_m3=pt.interp(region) / max(interp_fraction, 1e-12),
        refill_sigma_m3=pt.refill(region),
        unmodelled_bias_m3=pt.unmodelled(region),
        correction_residual_m3=pt.residual * float(region.sum()) * grid.cell_area,
        stable_cells=int(stable.sum()),
        change_area_m2=float(region.sum()) * grid.cell_area,
        part_area_m2={k: float(m.sum()) * grid.cell_area for k, m in parts.items()},
        unclassified_m3={k: float((bound_m3 or {}).get(k, 0.0)) for k in ("net", "cut", "fill")},
        terms_m3=terms,  # one-sigma: area model, refilled share, refill error, leftover bias, extras
        variogram={"lag_m": lags.tolist(), "gamma_m2": gamma.tolist(), "pairs": npairs.tolist()},
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
    (``unmodelled``); see :func:`volume_uncertainty`."""

    def __init__(
        self, diff, valid, stable, grid: GridSpec, filled_mask, own, fill_sigma, fraction: float, surface: bool
    ):
        self.cell_area, self.fraction = grid.cell_area, fraction
        self.filled = np.zeros(valid.shape, bool) if filled_mask is None else filled_mask & valid
        self.shared = self.filled if own is None else self.filled & ~own  # interpolated in the difference
        self.absd = np.abs(np.where(valid, diff, 0.0))
        self.labels, self.n_patches = ndimage.label(self.filled)
        self.fs = np.zeros(valid.shape) if fill_sigma is None else np.where(self.filled, fill_sigma, 0.0)
        self.leftover = leftover_bias(diff, stable, grid.cell)
        # the correction surface's residual systematic error where it cannot be seen: the spread of
        # its leftover over the stable ground, carried fully correlated over the part's area
        seen = self.leftover[stable & np.isfinite(self.leftover)] if surface else np.empty(0)  # no surface, none
        self.residual = float(np.sqrt(np.mean(np.square(seen)))) if seen.size else 0.0

    def terms(self, m: np.ndarray, area_model: float, extras: float) -> list[float]:
        """The one-sigma terms of the part ``m``, in the order of :data:`TERMS`."""
        return [area_model, self.interp(m), self.refill(m), self.unmodelled(m), extras]

    def interp(self, m: np.ndarray) -> float:
        return self.fraction * float(self.absd[m & self.shared].sum()) * self.cell_area

    def refill(self, m: np.ndarray) -> float:
        labels, n = self.labels, self.n_patches
        per_patch = ndimage.sum(np.where(m, self.fs, 0.0), labels, np.arange(1, n + 1)) * self.cell_area
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
    from ..compensation.stable import noise_sigma

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
    num = ndimage.gaussian_filter(np.where(w > 0, residual, 0.0), s)
    den = ndimage.gaussian_filter(w, s)
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


def thresholded_volumes(
    diff: np.ndarray, lod: float | np.ndarray, cell_area: float, min_cells: int = 1
) -> dict[str, float]:
    """net/cut/fill (m^3, cut and fill positive, net = fill - cut) over cells with |d| >= lod
    (``lod`` a float or a per-cell array); with ``min_cells`` > 1, connected same-sign patches
    smaller than that are dropped too (a spatial-coherence filter against isolated noise)."""
    keep = np.isfinite(diff) & (np.abs(diff) >= lod)
    if min_cells > 1:
        keep = patches(keep & (diff > 0), min_cells) | patches(keep & (diff < 0), min_cells)
    d = np.where(keep, diff, 0.0)
    fill = float(d[d > 0].sum() * cell_area)
    cut = float(-d[d < 0].sum() * cell_area)
    return {"net": fill - cut, "cut": cut, "fill": fill, "area_m2": float(keep.sum() * cell_area)}
