"""The spatially correlated error of a volume (Rolstad et al. 2009; Anderson 2019): the stable
residuals' semivariogram fitted by ``nugget + psill * sph(h, range)``; over ``n`` cells of area ``A``
the variance is ``n * nugget * cell^4 + A^2 * psill * f(A, range)`` plus the correction's level."""

from __future__ import annotations

import math

import numpy as np

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
    """Rolstad et al. (2009): a disc-equivalent area's mean variance as a fraction of the point variance."""
    if area <= 0 or rng <= 0:
        return 0.0
    radius = math.sqrt(area / math.pi)
    if radius >= rng:
        return math.pi * rng * rng / (5 * area)
    q = radius / rng
    return 1 - q + q**3 / 5


def region_sigma(n_cells: int, cell: float, model: dict[str, float], bias_sigma: float = 0.0) -> float:
    """One-sigma volume uncertainty (m^3) over ``n_cells`` cells."""
    if n_cells <= 0:
        return 0.0
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
