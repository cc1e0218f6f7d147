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
    cut = float(-d[d < 0].sum() * cell_area)
    return {"net": fill - cut, "cut": cut, "fill": fill, "cells": int(ok.sum()),
            "area_m2": float(ok.sum() * cell_area)}
