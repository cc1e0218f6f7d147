"""Difference raster and the paper's volume ``V = S_g * sum(H_after - H_before - d_i)``:
fill (material added, >= 0), cut (material removed, >= 0) and net = fill - cut."""

from __future__ import annotations

import numpy as np


def difference(h_after: np.ndarray, h_before: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
    """``H_after - H_before - d_i``; NaN where either grid is empty."""
    d = h_after - h_before
    return d if offset is None else d - offset


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
