"""Robust statistics and low-order polynomial surfaces on grids (the building blocks of the
stable-ground search and the bias correction)."""

from __future__ import annotations

import numpy as np

_MAX_FIT = 150_000  # cells used per least-squares fit


def nmad(values: np.ndarray) -> float:
    """Normalized median absolute deviation (1.4826 x MAD) of the finite values."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def residual_stats(residual: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """mean, std, nmad, rmse and n_cells of ``residual`` on ``mask``."""
    r = residual[mask & np.isfinite(residual)]
    if r.size == 0:
        return {"mean": float("nan"), "std": float("nan"), "nmad": float("nan"), "rmse": float("nan"), "n_cells": 0}
    return {
        "mean": float(r.mean()),
        "std": float(r.std()),
        "nmad": nmad(r),
        "rmse": float(np.sqrt(np.mean(r * r))),
        "n_cells": int(r.size),
    }


def _terms(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    cols = [np.ones_like(x)] + ([x, y] if degree >= 1 else []) + ([x * x, x * y, y * y] if degree >= 2 else [])
    return np.stack(cols, axis=-1)


_TERM_NAMES = ("1", "x", "y", "x2", "xy", "y2")


def _lstsq(a: np.ndarray, z: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least squares of the design matrix ``a`` (:func:`_terms`, centred and scaled: well conditioned) on
    ``z`` by its normal equations (a 6 x 6 system: an SVD of the n x 6 matrix took 2 ms a fit), by an SVD when they
    are singular."""
    aw = a * w[:, None]
    try:
        return np.linalg.solve(aw.T @ a, aw.T @ z)
    except np.linalg.LinAlgError:
        sw = np.sqrt(w)
        return np.linalg.lstsq(a * sw[:, None], z * sw, rcond=None)[0]


def fit_poly(x, y, diff, mask, degree: int, robust: bool = False):
    """(surface over the whole grid, coefficients, (cx, cy, scale)); Tukey-IRLS if ``robust``."""
    cx, cy = float(x[mask].mean()), float(y[mask].mean())  # centred and scaled on the masked cells (conditioning)
    s = float(max(np.ptp(x[mask]), np.ptp(y[mask]), 1e-9) / 2)
    xs, ys = (x - cx) / s, (y - cy) / s
    idx = np.flatnonzero(mask)
    if idx.size > _MAX_FIT:  # a regular subsample keeps large grids fast
        idx = idx[:: -(-idx.size // _MAX_FIT)]
    px, py, z = xs.ravel()[idx], ys.ravel()[idx], diff.ravel()[idx]
    a = _terms(px, py, degree)  # the same design matrix for every reweighting
    coef = _lstsq(a, z, np.ones_like(z))
    for _ in range(8 if robust else 0):
        r = z - a @ coef
        c = 4.685 * max(nmad(r), 1e-6)
        w = np.clip(1 - (r / c) ** 2, 0, None) ** 2
        if np.count_nonzero(w) <= degree * 3 + 1:
            break
        coef = _lstsq(a, z, w)
    return _terms(xs, ys, degree) @ coef, coef, (cx, cy, s)


def patches(mask: np.ndarray, min_cells: int) -> np.ndarray:
    """Cells of ``mask`` in 8-connected patches of at least ``min_cells`` cells."""
    from scipy import ndimage

    if min_cells <= 1 or not mask.any():
        return mask
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    ok = np.bincount(labels.ravel(), minlength=n + 1) >= min_cells
    ok[0] = False
    return ok[labels]
