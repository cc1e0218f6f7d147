"""Stable-ground bias correction of a DEM of difference (generalises the paper's plane offset): a
constant, plane or degree-2 surface (lowered to a plane when stable ground lies on one side of the
change only) fitted by least squares on the stable cells of :mod:`.stable` and subtracted."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.types import GridSpec
from .robust import _TERM_NAMES, fit_poly, residual_stats
from .stable import find_stable, largest_gap_deg
from .strips import strip_levels, strip_steps


@dataclass(frozen=True)
class Mode:
    """What a ``--correction`` value means, decoded here once."""

    degree: int | None  # degree of the polynomial fitted on stable ground (None: no surface)
    coefficients: int  # parameters fitted (degrees of freedom the uncertainty loses)
    paper_plane: bool = False  # subtract the paper's plane offset d_i first


MODES = {
    "surface": Mode(2, 6),
    "plane": Mode(1, 3),
    "constant": Mode(0, 1),
    "none": Mode(None, 0),
    "paper-plane": Mode(None, 0, paper_plane=True),
}
METHODS = tuple(name for name, mode in MODES.items() if not mode.paper_plane)  # surfaces fitted here


@dataclass
class CorrectionResult:
    """``corrected = diff - surface``; ``change_mask``: valid cells off stable ground; ``params``."""

    corrected: np.ndarray
    surface: np.ndarray
    stable_mask: np.ndarray
    change_mask: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)


def fit_surface(
    diff: np.ndarray, stable_mask: np.ndarray, grid: GridSpec, method: str = "surface"
) -> tuple[np.ndarray, dict[str, Any]]:
    """Least-squares ``method`` surface on the stable cells: (surface, params: method, terms,
    coefficients (scaled local frame), centre_local, scale_m, residuals after and before)."""
    if method not in METHODS:
        raise ValueError(f"unknown correction method {method!r} (expected one of {METHODS})")
    mask = stable_mask & np.isfinite(diff)
    degree = MODES[method].degree
    params: dict[str, Any] = {"method": method}
    if degree is None or mask.sum() < 6:
        surface = np.zeros(diff.shape)
        if degree is not None:
            params["note"] = "too few stable cells: no correction applied"
    else:
        x, y = grid.centers_local()
        surface, coef, (cx, cy, s) = fit_poly(x, y, diff, mask, degree)
        terms, coefficients = list(_TERM_NAMES[: len(coef)]), [float(c) for c in coef]
        params.update(terms=terms, coefficients=coefficients, centre_local=[cx, cy], scale_m=s)
    params["residuals"] = residual_stats(diff - surface, mask)
    params["residuals_before"] = residual_stats(diff, mask)
    return surface, params


def apply(diff: np.ndarray, method: str, grid: GridSpec, user_mask: np.ndarray | None = None) -> CorrectionResult:
    """Find stable ground (whatever the method: ``none`` still has residual statistics), fit the
    ``method`` surface on it, lowered to what it supports (a curve needs it all around the change, a
    plane one side: :func:`.stable.largest_gap_deg`, a handful a constant), and subtract it."""
    stable = find_stable(diff, grid.cell, user_mask=user_mask)[0]
    valid = np.isfinite(diff)
    used = method
    if method in ("surface", "plane") and stable.sum() < 30:
        used = "constant"
    elif method == "surface" and largest_gap_deg(stable, valid & ~stable) > 180.0:
        used = "plane"
    surface, params = fit_surface(diff, stable, grid, used)
    found = strip_steps(diff - surface, stable, grid) if used in ("surface", "plane") else None
    if found is not None:  # a survey's flight strips at offsets: their levels subtracted too
        surface, params["strips"] = surface + strip_levels(found, grid), found
        params["residuals"] = residual_stats(diff - surface, stable & valid)
    params["method"], params["fitted"] = method, used
    surface = np.where(valid, surface, np.nan)
    params.update(stable_cells=int(stable.sum()), stable_fraction=float(stable.sum() / max(valid.sum(), 1)))
    return CorrectionResult(diff - surface, surface, stable, valid & ~stable, params)
