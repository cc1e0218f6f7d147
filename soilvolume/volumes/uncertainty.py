"""Level of detection (GCD-style ``z * NMAD`` of the stable residuals) and volume uncertainty: the
correlated error, the refills', the correction's leftover bias, a caller's terms. The correlated error
(Rolstad et al. 2009; Anderson 2019): the stable residuals' semivariogram fitted by ``nugget + psill *
sph(h, range)``; over ``n`` cells of area ``A`` the variance is ``n * nugget * cell^4 + A^2 * psill *
f(A, range)`` plus the correction's level."""

from __future__ import annotations

import math
from statistics import NormalDist
from typing import Any

import numpy as np
import scipy

from ..compensation.robust import nmad
from ..compensation.stable import noise_sigma
from ..core.types import GridSpec

INTERP_FRACTION = 0.15


def interp_fraction(refilled: np.ndarray) -> float:
    """Refilled change volume's one-sigma share by the radius (cells) of ``refilled``'s area-weighted typical patch:
    falls as 1 / radius (30-80 % on ~2-cell holes, under 5 % on 6)."""
    labels, n = scipy.ndimage.label(refilled)
    size = np.bincount(labels.ravel())[1:].astype(float)
    radius = max(1.0, float(np.sqrt((size * size).sum() / size.sum() / np.pi))) if n else 1.0
    return float(min(0.5, max(INTERP_FRACTION, 1.0 / radius)))


def z_value(confidence: float = 0.95) -> float:
    """Two-sided normal quantile (1.96 for 95 %)."""
    return NormalDist().inv_cdf(0.5 + confidence / 2)


#: the one-sigma terms (m^3) of ``terms_m3[part]``, in order (extras: what a caller adds)
TERMS = ("area_model", "refilled_share", "refill_error", "leftover_bias", "extras")


def volume_uncertainty(
    diff_corrected: np.ndarray,
    stable_mask: np.ndarray,
    change_mask: np.ndarray | None,
    grid: GridSpec,
    confidence: float = 0.95,
    *,
    n_coef: int = 6,
    fills: tuple = (None, None, None),
    extra_sigma: dict[str, float] | None = None,
    counted: np.ndarray | None = None,
    bound_m3: dict[str, float] | None = None,
) -> dict[str, Any]:
    """± (m^3) at ``confidence`` over ``change_mask`` (all if None), the model's figures, :data:`TERMS`; ``n_coef``: the
    correction's (0: no surface, no leftover bias), ``fills``: the refilled cells, those filled in their own survey and
    their one-sigma error (m), ``counted``: a tile's core, ``bound_m3``: added as is."""
    d, valid = diff_corrected, np.isfinite(diff_corrected)
    stable = stable_mask & valid
    valid = valid if counted is None else valid & counted
    region = valid if change_mask is None else change_mask & valid
    vario = semivariogram(d, stable, grid.cell)
    model = fit_spherical(*vario)
    b = bias_sigma(int(stable.sum()), grid.cell, model, n_coef) if n_coef else 0.0
    parts = {"net": region, "cut": region & (d < 0), "fill": region & (d > 0), "net_compared_area": valid}
    beyond, shared, residual = _beyond_area(d, valid, stable, grid, fills, n_coef > 0)
    extra, area = extra_sigma or {}, grid.cell_area
    terms = {
        k: [region_sigma(int(m.sum()), grid.cell, model, b), *beyond(m), extra.get(k, 0.0)] for k, m in parts.items()
    }
    out: dict[str, Any] = widen({k: z_value(confidence) * float(np.linalg.norm(t)) for k, t in terms.items()}, bound_m3)
    sigma = nmad(d[stable]) if stable.any() else float("nan")
    out.update(confidence=confidence, sigma_m=sigma, lod_m=_lod(d[stable], sigma, confidence))
    out.update(nugget_m2=model["nugget"], psill_m2=model["psill"], range_m=model["range"], bias_sigma_m=b)
    out.update(
        interpolated_m3=float(np.abs(d[region & shared]).sum()) * area,
        refill_sigma_m3=terms["net"][2],
        unmodelled_bias_m3=terms["net"][3],
        correction_residual_m3=residual * float(region.sum()) * area,
        stable_cells=int(stable.sum()),
        change_area_m2=float(region.sum()) * area,
        part_area_m2={k: float(m.sum()) * area for k, m in parts.items()},
        unclassified_m3={k: float((bound_m3 or {}).get(k, 0.0)) for k in ("net", "cut", "fill")},
        terms_m3=terms,  # one-sigma: area model, refilled share, refill error, leftover bias, extras
        variogram={"lag_m": vario[0].tolist(), "gamma_m2": vario[1].tolist(), "pairs": vario[2].tolist()},
    )
    return out


def widen(half: dict[str, float], bound: dict[str, float] | None) -> dict[str, float]:
    """Half-widths (m3) widened by the unattributed ``bound`` (all or none: it adds as it is)."""
    b = bound or {}
    return {k: v + float(b.get("net" if k == "net_compared_area" else k, 0.0)) for k, v in half.items()}


def _beyond_area(diff, valid, stable, grid: GridSpec, fills: tuple, surface: bool):
    """(a part's terms beyond its area's, m3: the error of the refilled patches in it or along its edge, the larger of
    that measured on test holes in the change where they fit (``fills``' fourth: each patch's one-sigma error of its
    mean, NaN where unmeasured) and the refilled share of their |volume| of the part's sign (10-22 % off on synthetic
    pairs); the refills' ``fill_sigma`` per patch; the leftover bias. Then the cells refilled in the difference; the
    correction's residual m)."""
    (filled_mask, own, fill_sigma, *more), area = fills, grid.cell_area
    in_change = more[0] if more and more[0] is not None else np.full(valid.shape, np.nan)
    given = np.zeros(valid.shape, bool) if filled_mask is None else filled_mask
    filled = given & valid
    shared = filled if own is None else filled & ~own  # interpolated in the difference
    fraction = interp_fraction(given if own is None else given & ~own)
    absd = np.abs(np.where(valid, diff, 0.0))
    labels, n = scipy.ndimage.label(filled)
    fs = np.zeros(valid.shape) if fill_sigma is None else np.where(filled, fill_sigma, 0.0)
    leftover = leftover_bias(diff, stable, grid.cell)
    seen = leftover[stable & np.isfinite(leftover)] if surface else np.empty(0)  # no surface, none
    residual = float(np.sqrt(np.mean(np.square(seen)))) if seen.size else 0.0

    def terms(m: np.ndarray) -> list[float]:
        per_patch = scipy.ndimage.sum(np.where(m, fs, 0.0), labels, np.arange(1, n + 1)) * area
        signed = abs(float(np.nansum(np.where(m, leftover, 0.0)))) * area  # fully correlated over the part
        hit = np.unique(labels[scipy.ndimage.binary_dilation(m) & shared & np.isfinite(in_change)])
        tested = np.isin(labels, hit) & shared  # patches in the part or along its edge: they may hide some of it
        measured = scipy.ndimage.sum(np.where(tested, in_change, 0.0), labels, np.arange(1, n + 1)) * area
        signs = np.sign(diff[m & valid])
        alike = m | (np.sign(diff) == signs[0]) if signs.size and (signs == signs[0]).all() else True
        assumed = fraction * float(absd[tested & alike].sum()) * area  # the share of their change of the part's sign
        return [
            max(float(np.sqrt(np.sum(np.square(measured)))), assumed)
            + fraction * float(absd[m & shared & ~tested].sum()) * area,
            float(np.sqrt(np.sum(np.square(per_patch)))) if n else 0.0,
            float(np.hypot(signed, residual * float(m.sum()) * area)),
        ]

    return terms, shared, residual


def statistic_bias(skews: tuple, refilled: np.ndarray, parts: dict[str, np.ndarray], cell_area: float) -> dict:
    """One-sigma volume (m3) per part of the cell statistic's bias: ``skews`` differenced, summed (not refilled)."""
    signed = (sign * np.nan_to_num(sk) for sign, sk in zip((1.0, -1.0), skews, strict=True) if sk is not None)
    d = sum(signed, np.zeros(refilled.shape))
    d[refilled] = 0.0
    return {k: abs(float(d[m].sum())) * cell_area for k, m in parts.items()}


def detection_level(diff: np.ndarray, stable: np.ndarray, confidence: float = 0.95) -> float:
    """A cell's LoD (m): :func:`_lod` of the stable residuals, at most twice the neighbour noise's."""
    r = diff[stable & np.isfinite(diff)]
    cap = 2.0 * z_value(confidence) * noise_sigma(diff)  # NaN with too few neighbours
    known = [v for v in (_lod(r, nmad(r), confidence), cap) if v is not None and np.isfinite(v)]
    return float(min(known)) if known else 0.0


def leftover_bias(residual: np.ndarray, stable: np.ndarray, cell: float, scale_m: float = 10.0) -> np.ndarray:
    """The stable residuals smoothed over ``scale_m`` into the change (a dome not quite of degree 2 leaves mm)."""
    w = (stable & np.isfinite(residual)).astype(float)
    s = max(1.0, scale_m / cell)
    num = scipy.ndimage.gaussian_filter(np.where(w > 0, residual, 0.0), s)
    den = scipy.ndimage.gaussian_filter(w, s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.05, num / den, np.nan)


def _lod(stable_residuals: np.ndarray, sigma: float, confidence: float) -> float | None:
    """LoD at ``confidence``: z x NMAD, or the |residuals|' quantile when heavier-tailed (usually)."""
    if not np.isfinite(sigma):
        return None
    r = np.abs(stable_residuals[np.isfinite(stable_residuals)])
    empirical = float(np.quantile(r, confidence)) if r.size >= 20 else 0.0
    return max(z_value(confidence) * sigma, empirical)


N_LAGS = 24


def semivariogram(residual: np.ndarray, mask: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Isotropic semivariogram of the masked residuals by shifts: (lags_m, gamma_m2, n_pairs) up to half the extent."""
    z = np.where(mask & np.isfinite(residual), residual, np.nan)
    rr, cc = np.nonzero(np.isfinite(z))
    if rr.size < 2:
        return np.empty(0), np.empty(0), np.empty(0, int)
    extent = max(np.ptp(rr), np.ptp(cc)) + 1
    top = max(1, min(extent // 2, extent - 1))
    lags = np.unique(np.round(np.geomspace(1, top, N_LAGS)).astype(int))
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
    """The pair-weighted spherical fit {nugget, psill, range}: levels exact per range, the range on a refined log
    grid."""
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
    """Per range, the least cost and (nugget, psill) within [0, ``cap``] (the free solution, else the box's edges)."""
    b = spherical(lags[None, :], 0.0, 1.0, ranges[:, None])  # (R, L): the model's shape at each lag
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
    """Rolstad et al. (2009): a disc-equivalent area's mean variance as a fraction of the point variance."""
    if area <= 0 or rng <= 0:
        return 0.0
    radius = math.sqrt(area / math.pi)
    if radius >= rng:
        return math.pi * rng * rng / (5 * area)
    q = radius / rng
    return 1 - q + q**3 / 5


def region_sigma(n_cells: int, cell: float, model: dict[str, float], bias_sigma: float = 0.0) -> float:
    """One-sigma volume uncertainty (m^3) over ``n_cells`` cells (0 over none)."""
    area = n_cells * cell * cell
    var_unc = n_cells * model["nugget"] * cell**4
    var_cor = area * area * model["psill"] * correlated_fraction(area, model["range"])
    var_sys = (area * bias_sigma) ** 2
    return math.sqrt(var_unc + var_cor + var_sys)


def bias_sigma(n_stable: int, cell: float, model: dict[str, float], n_coef: int) -> float:
    """One-sigma error of the correction's level: the stable ground's mean error, inflated by the coefficients."""
    if n_stable <= 0:
        return 0.0
    area = n_stable * cell * cell
    var_mean = model["nugget"] / n_stable + model["psill"] * correlated_fraction(area, model["range"])
    return math.sqrt(max(n_coef, 1) * var_mean)
