"""The paper's volume ``V = S_g * sum(H_after - H_before - d_i)``: fill (added, >= 0), cut
(removed, >= 0) and net = fill - cut."""

from __future__ import annotations

import numpy as np

from ..compensation.robust import patches


def budget(diff: np.ndarray, cell_area: float, mask: np.ndarray | None = None) -> dict[str, float]:
    """Cut, fill and net (m3) over the finite cells of ``diff`` (and ``mask`` when given)."""
    ok = np.isfinite(diff) if mask is None else np.isfinite(diff) & mask
    d = diff[ok]
    fill = float(d[d > 0].sum() * cell_area)
    cut = float(-d[d < 0].sum() * cell_area) + 0.0  # + 0.0: no -0.0 cut
    return {"net": fill - cut, "cut": cut, "fill": fill, "cells": int(ok.sum()), "area_m2": float(ok.sum() * cell_area)}


def signed_budget(diff: np.ndarray, fill_area: np.ndarray, cut_area: np.ndarray, cell_area: float) -> dict:
    """Fill over the fill areas, cut over the cut areas (m3), net = fill - cut."""
    fill = float(np.nansum(np.where(fill_area, diff, 0.0)) * cell_area)
    cut = float(-np.nansum(np.where(cut_area, diff, 0.0)) * cell_area) + 0.0
    cells = int((fill_area | cut_area).sum())
    return {"net": fill - cut, "cut": cut, "fill": fill, "cells": cells, "area_m2": cells * cell_area}


def refilled_budget(diff: np.ndarray, filled_mask: np.ndarray, cell_area: float) -> dict:
    """The refilled cells' count, area and net volume."""
    d = np.where(filled_mask, diff, 0.0)
    n = int(filled_mask.sum())
    return {"filled_cells": n, "filled_area_m2": n * cell_area, "filled_net_m3": float(np.nansum(d) * cell_area)}


def thresholded_volumes(
    diff: np.ndarray, lod: float | np.ndarray, cell_area: float, min_cells: int = 1
) -> dict[str, float]:
    """Net, cut, fill (m^3) over cells with |d| >= ``lod``, without same-sign patches under ``min_cells`` (isolated
    noise)."""
    keep = np.isfinite(diff) & (np.abs(diff) >= lod)
    if min_cells > 1:
        keep = patches(keep & (diff > 0), min_cells) | patches(keep & (diff < 0), min_cells)
    d = np.where(keep, diff, 0.0)
    fill = float(d[d > 0].sum() * cell_area)
    cut = float(-d[d < 0].sum() * cell_area)
    return {"net": fill - cut, "cut": cut, "fill": fill, "area_m2": float(keep.sum() * cell_area)}
