"""Stable-ground bias correction of a DEM of difference (generalises the paper's plane offset).

Stable cells are found iteratively: fit a degree-2 surface robustly, flag cells whose residual
exceeds k x NMAD (or a given LoD) as change, dilate the change areas, refit on the rest. The
correction surface (constant, plane or degree-2 polynomial) is then least squares on the stable
cells and subtracted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from .types import GridSpec

METHODS = ("surface", "plane", "constant", "none")
_DEGREE = {"surface": 2, "plane": 1, "constant": 0}
_MAX_FIT = 150_000  # cells used per least-squares fit


@dataclass
class CorrectionResult:
    """``corrected = diff - surface``; ``change_mask`` = valid cells outside the stable ground
    (the dilated change areas); ``params`` as :func:`fit_surface` returns them."""

    corrected: np.ndarray
    surface: np.ndarray
    stable_mask: np.ndarray
    change_mask: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)


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
        return {"mean": float("nan"), "std": float("nan"), "nmad": float("nan"),
                "rmse": float("nan"), "n_cells": 0}
    return {"mean": float(r.mean()), "std": float(r.std()), "nmad": nmad(r),
            "rmse": float(np.sqrt(np.mean(r * r))), "n_cells": int(r.size)}


def _terms(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    cols = [np.ones_like(x)]
    if degree >= 1:
        cols += [x, y]
    if degree >= 2:
        cols += [x * x, x * y, y * y]
    return np.stack(cols, axis=-1)


_TERM_NAMES = ("1", "x", "y", "x2", "xy", "y2")


def _scaled(x: np.ndarray, y: np.ndarray, mask: np.ndarray):
    """Centre and scale coordinates on the masked cells (conditioning)."""
    cx, cy = float(x[mask].mean()), float(y[mask].mean())
    s = float(max(np.ptp(x[mask]), np.ptp(y[mask]), 1e-9) / 2)
    return (x - cx) / s, (y - cy) / s, (cx, cy, s)


def _lstsq(xs, ys, z, w, degree: int) -> np.ndarray:
    a = _terms(xs, ys, degree)
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(a * sw[:, None], z * sw, rcond=None)
    return coef


def _poly_fit(x, y, diff, mask, degree: int, robust: bool = False):
    """(surface over the whole grid, coefficients, (cx, cy, scale)); Tukey-IRLS if ``robust``."""
    xs, ys, frame = _scaled(x, y, mask)
    idx = np.flatnonzero(mask)
    if idx.size > _MAX_FIT:  # a regular subsample keeps large grids fast
        idx = idx[:: -(-idx.size // _MAX_FIT)]
    px, py, z = xs.ravel()[idx], ys.ravel()[idx], diff.ravel()[idx]
    w = np.ones_like(z)
    coef = _lstsq(px, py, z, w, degree)
    for _ in range(8 if robust else 0):
        r = z - _terms(px, py, degree) @ coef
        c = 4.685 * max(nmad(r), 1e-6)
        w = np.clip(1 - (r / c) ** 2, 0, None) ** 2
        if np.count_nonzero(w) <= degree * 3 + 1:
            break
        coef = _lstsq(px, py, z, w, degree)
    return _terms(xs, ys, degree) @ coef, coef, frame


def _disk(radius_cells: float) -> np.ndarray:
    r = int(np.ceil(radius_cells))
    yy, xx = np.mgrid[-r: r + 1, -r: r + 1]
    return xx * xx + yy * yy <= radius_cells * radius_cells + 1e-9


def _drop_specks(change: np.ndarray, min_cells: int) -> np.ndarray:
    """Change cells in 8-connected patches of at least ``min_cells`` cells (isolated noise
    extremes are not change areas)."""
    if min_cells <= 1 or not change.any():
        return change
    labels, n = ndimage.label(change, structure=np.ones((3, 3), bool))
    ok = np.bincount(labels.ravel(), minlength=n + 1) >= min_cells
    ok[0] = False
    return ok[labels]


def stable_cells(
    diff: np.ndarray,
    cell: float,
    *,
    lod: float | None = None,
    dilate_m: float = 2.0,
    user_mask: np.ndarray | None = None,
    iterations: int = 5,
    k: float = 3.0,
    min_fraction: float = 0.05,
    min_change_cells: int = 3,
) -> np.ndarray:
    """Cells of ``diff`` taken as stable ground. With ``user_mask`` (True = stable) that mask
    (restricted to valid cells) is returned. Otherwise iterate: degree-2 fit, change =
    |residual| > ``lod`` (or ``k`` x NMAD) in patches of >= ``min_change_cells`` cells, dilate
    change by ``dilate_m``, refit on the rest."""
    valid = np.isfinite(diff)
    if user_mask is not None:
        return valid & user_mask.astype(bool)
    if valid.sum() < 12:
        return valid
    y, x = np.mgrid[0: diff.shape[0], 0: diff.shape[1]] * float(cell)
    stable = valid
    disk = _disk(dilate_m / cell) if dilate_m > 0 else None
    for it in range(iterations):
        surface, _, _ = _poly_fit(x, y, diff, stable, 2, robust=it == 0)
        resid = diff - surface
        thr = lod if lod is not None else k * nmad(resid[stable])
        change = _drop_specks(valid & (np.abs(resid) > thr), min_change_cells)
        if disk is not None and change.any():
            change = ndimage.binary_dilation(change, disk)
        new = valid & ~change
        if new.sum() < max(12, min_fraction * valid.sum()):
            break
        if np.array_equal(new, stable):
            break
        stable = new
    return stable


def fit_surface(
    diff: np.ndarray, stable_mask: np.ndarray, grid: GridSpec, method: str = "surface"
) -> tuple[np.ndarray, dict[str, Any]]:
    """Least-squares correction surface on the stable cells: ``surface`` (degree-2 polynomial),
    ``plane``, ``constant`` or ``none`` (zeros). Returns (surface (rows, cols), params) with
    params = method, terms, coefficients (in scaled local coordinates), centre_local, scale_m,
    and ``residuals`` (mean, std, nmad, rmse, n_cells of diff - surface on stable cells)."""
    if method not in METHODS:
        raise ValueError(f"unknown correction method {method!r} (expected one of {METHODS})")
    mask = stable_mask & np.isfinite(diff)
    degree = _DEGREE.get(method)
    params: dict[str, Any] = {"method": method}
    if degree is None or mask.sum() < 6:
        surface = np.zeros(diff.shape)
        if degree is not None:
            params["note"] = "too few stable cells: no correction applied"
    else:
        x, y = grid.centers_local()
        surface, coef, (cx, cy, s) = _poly_fit(x, y, diff, mask, degree)
        n = len(coef)
        params.update(terms=list(_TERM_NAMES[:n]), coefficients=[float(c) for c in coef],
                      centre_local=[cx, cy], scale_m=s)
    params["residuals"] = residual_stats(diff - surface, mask)
    params["residuals_before"] = residual_stats(diff, mask)
    return surface, params


def apply(
    diff: np.ndarray,
    method: str,
    grid: GridSpec,
    *,
    user_mask: np.ndarray | None = None,
    lod: float | None = None,
    dilate_m: float = 2.0,
    iterations: int = 5,
) -> CorrectionResult:
    """Find stable ground, fit the ``method`` surface on it and subtract it. Stable ground is
    found the same way whatever the method (so ``none`` still yields residual statistics)."""
    stable = stable_cells(diff, grid.cell, lod=lod, dilate_m=dilate_m, user_mask=user_mask,
                          iterations=iterations)
    surface, params = fit_surface(diff, stable, grid, method)
    surface = np.where(np.isfinite(diff), surface, np.nan)
    valid = np.isfinite(diff)
    params["stable_cells"] = int(stable.sum())
    params["stable_fraction"] = float(stable.sum() / max(valid.sum(), 1))
    return CorrectionResult(diff - surface, surface, stable, valid & ~stable, params)
