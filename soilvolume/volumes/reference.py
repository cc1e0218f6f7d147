"""A survey against a reference surface (a design, or an earlier DEM): their agreement on unchanged
ground, the surface's terms of the interval, the verdict. Nothing is registered nor, by default,
corrected against a surface (it would absorb the works), so a datum offset shows only here: the
median of (survey - surface) on unchanged cells must be within the level of detection."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy

from ..compensation.robust import nmad
from ..core.types import GridSpec
from ..options import Options
from .quality import VERDICTS
from .results import Volumes
from .uncertainty import bias_sigma, z_value

MIN_CELLS = 30  # fewer unchanged cells than this cannot tell an offset
RING = 1  # cells around the change areas whose sub-detection difference the volumes may miss
TERMS = ("resampling", "given", "datum", "truncation", "outline")  # the surface's terms of the interval (m³)
SEVERITY = {"caution": 1, "unreliable": 2}
_SIGNS = (("fill", 1.0), ("cut", -1.0))


def agreement(filled: np.ndarray, unchanged: np.ndarray, lod_m: float, cell_area: float) -> dict:
    """report.json's ``reference.agreement``: median and NMAD of (survey - surface) on ``unchanged``."""
    d = filled[unchanged & np.isfinite(filled)]
    return {
        "cells": int(d.size),
        "area_m2": float(d.size * cell_area),
        "median_m": float(np.median(d)) if d.size else float("nan"),
        "nmad_m": float(nmad(d)) if d.size else float("nan"),
        "lod_m": float(lod_m),
    }


def check(agree: dict) -> tuple[str, str]:
    """(severity, sentence) of the survey's agreement with the surface; severity "" when it agrees."""
    n, med, spread, lod = agree["cells"], agree["median_m"], agree["nmad_m"], agree["lod_m"]
    if n < MIN_CELLS:
        return (
            "caution",
            f"too little unchanged ground ({agree['area_m2']:,.0f} m²) to check that the survey and the design "
            "share a datum: the volumes rest on both being georeferenced alike",
        )
    said = f"over {agree['area_m2']:,.0f} m² of unchanged ground (median {med:+.3f} m, NMAD {spread:.3f} m)"
    if abs(med) > lod:
        return (
            "unreliable",
            f"the survey is offset from the design by {med:+.2f} m {said}, beyond the level of detection "
            f"({lod:.3f} m): the survey or the design is offset (datum, geoid or georeferencing), and the volumes "
            "count that offset as earthworks",
        )
    return "", f"the survey agrees with the design {said}, within the level of detection ({lod:.3f} m)"


def merge(quality: dict, found: tuple[str, str]) -> dict:
    """The verdict with the agreement's sentence first (alone if reliable: the registration's does not apply)."""
    severity, sentence = found
    worst = max(VERDICTS.index(quality["verdict"]), SEVERITY.get(severity, 0))
    kept = quality["messages"] if quality["verdict"] != VERDICTS[0] else []
    return {"verdict": VERDICTS[worst], "trusted": worst == 0, "messages": [sentence, *kept]}


def _sided(diff: np.ndarray, cells: dict[str, np.ndarray], cell_area: float, z: float, share: float = 1.0) -> dict:
    """``share`` of the same-signed difference over the fill and cut ``cells`` (m³ at ``z``); the net in quadrature."""
    d = np.nan_to_num(diff)
    out = {k: float(z * share * np.clip(s * d[cells[k]], 0.0, None).sum() * cell_area) for k, s in _SIGNS}
    out["net"] = float(np.hypot(out["fill"], out["cut"]))
    return out


def with_surface(vols: Volumes, sigma: np.ndarray, options: Options, grid: GridSpec) -> Volumes:
    """The volume step's result with the surface's :data:`TERMS` (``sigma``: its per-cell error) in quadrature."""
    u, cut, change = vols.uncertainty, vols.cut_mask, vols.change_mask
    counted = {"net": change, "cut": cut & change, "fill": change & ~cut}
    model = {"nugget": u["nugget_m2"], "psill": u["psill_m2"], "range": u["range_m"]}
    datum = bias_sigma(u["stable_cells"], grid.cell, model, 1) if options.correction == "none" else 0.0
    z, terms = z_value(options.lod_confidence), {part: {} for part in TERMS[:3]}
    for key, mask in counted.items():  # resampling: independent; the given level and the datum: common
        s, area = np.nan_to_num(sigma[mask]), float(mask.sum()) * grid.cell_area
        terms["resampling"][key] = float(z * np.sqrt(np.sum(s * s)) * grid.cell_area)
        terms["given"][key] = float(z * options.design_uncertainty * area)
        terms["datum"][key] = float(z * datum * area)
    # truncation: the change below detection in the RING around the areas, not counted (a graded pad crossing contours)
    valid = np.isfinite(vols.diff)
    ring = {k: scipy.ndimage.binary_dilation(counted[k], iterations=RING) & ~counted["net"] & valid for k, _ in _SIGNS}
    terms["truncation"] = _sided(vols.diff, ring, grid.cell_area, z)
    # outline: the change areas' cells on the compared area's outline, known to half a cell: half their volume
    edge = valid & ~scipy.ndimage.binary_erosion(valid, border_value=0)
    terms["outline"] = _sided(vols.diff, {k: edge & counted[k] for k, _ in _SIGNS}, grid.cell_area, z, 0.5)
    out = {**u, "reference_m3": terms}
    for key in ("net", "cut", "fill"):
        out[key] = float(np.linalg.norm([u[key], *(terms[part][key] for part in TERMS)]))
    return replace(vols, uncertainty=out)
