"""A survey against a reference surface (a design, or an earlier DEM): whether they agree where
the surface is the existing ground, the surface's error terms of the volume, and the verdict.

Nothing is registered against a surface and no bias is removed by default (a design is not the
existing ground: fitting one onto it would absorb the works), so an offset between the survey's
and the surface's datum shows only here: on the cells the survey's change detection deems
unchanged, the median of (survey - surface) must be within the level of detection.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy

from ..compensation.robust import nmad
from ..core.types import GridSpec
from ..options import Options
from .results import Volumes
from .uncertainty import z_value
from .variogram import bias_sigma

MIN_CELLS = 30  # fewer unchanged cells than this cannot tell an offset
RING = 1  # cells around the change areas whose sub-detection difference the volumes may miss
TERMS = ("resampling", "given", "datum", "truncation", "outline")  # the surface's terms of the interval (m³)
VERDICTS = ("reliable", "use with caution", "not reliable")  # as volumes/quality
SEVERITY = {"caution": 1, "unreliable": 2}


def agreement(filled: np.ndarray, unchanged: np.ndarray, lod_m: float, cell_area: float) -> dict:
    """report.json's ``reference.agreement``: the median and NMAD of (survey - surface) on the
    ``unchanged`` cells, against the level of detection."""
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
    """The quality verdict with the agreement check's sentence first; a run whose verdict was
    reliable gets it instead of the registration sentence that does not apply."""
    severity, sentence = found
    worst = max(VERDICTS.index(quality["verdict"]), SEVERITY.get(severity, 0))
    kept = quality["messages"] if quality["verdict"] != VERDICTS[0] else []
    return {"verdict": VERDICTS[worst], "trusted": worst == 0, "messages": [sentence, *kept]}


def design_terms(
    counted: dict[str, np.ndarray], sigma_cell: np.ndarray, given_m: float, datum_m: float, cell_area: float, z: float
) -> dict:
    """The surface's share of the volume's interval (m³, at the ``z`` of the confidence), per
    budget (``counted``: net, cut, fill cell masks): its resampling error per cell
    (``sigma_cell``, independent between cells); a given uncertainty of the surface (``given_m``,
    one error common to the counted area: a design's level is one number); and the datum between
    survey and surface, known only as well as the unchanged ground measures it (``datum_m``, one
    sigma of its mean there; nothing removes it), common to the counted area too."""
    out: dict[str, dict[str, float]] = {"resampling": {}, "given": {}, "datum": {}}
    for key, mask in counted.items():
        s, area = np.nan_to_num(sigma_cell[mask]), float(mask.sum()) * cell_area
        out["resampling"][key] = float(z * np.sqrt(np.sum(s * s)) * cell_area)
        out["given"][key] = float(z * given_m * area)
        out["datum"][key] = float(z * datum_m * area)
    return out


def truncation(diff: np.ndarray, counted: dict[str, np.ndarray], cell_area: float, z: float) -> dict:
    """The change just below the detection level along the change areas (the ring of cells
    around the fill areas, and the cut areas, not counted; :data:`RING`), m³ at ``z``: what the
    areas' outline leaves out where the difference fades out slowly, as where a plan meets gently
    sloping ground (a graded pad crossing the terrain's contours). One sigma: that ring's
    same-signed difference; the net's, both in quadrature."""
    d, every = np.nan_to_num(diff), counted["net"]
    out = {}
    for key, sign in (("fill", 1.0), ("cut", -1.0)):
        ring = scipy.ndimage.binary_dilation(counted[key], iterations=RING) & ~every & np.isfinite(diff)
        out[key] = float(z * np.clip(sign * d[ring], 0.0, None).sum() * cell_area)
    out["net"] = float(np.hypot(out["fill"], out["cut"]))
    return out


def outline(diff: np.ndarray, counted: dict[str, np.ndarray], cell_area: float, z: float) -> dict:
    """The change areas' cells on the outline of the compared area (the survey's edge, or the
    surface's), m³ at ``z``: such a cell counts whole though the survey or the surface covers
    only part of it, so where the works run to the edge its volume is known to half a cell. One
    sigma: half their same-signed volume; the net's, both in quadrature."""
    valid = np.isfinite(diff)
    edge = valid & ~scipy.ndimage.binary_erosion(valid, border_value=0)
    d, out = np.nan_to_num(diff), {}
    for key, sign in (("fill", 1.0), ("cut", -1.0)):
        out[key] = float(z * 0.5 * np.clip(sign * d[edge & counted[key]], 0.0, None).sum() * cell_area)
    out["net"] = float(np.hypot(out["fill"], out["cut"]))
    return out


def with_terms(uncertainty: dict, terms: dict) -> dict:
    """The uncertainty record with the surface's terms added in quadrature to net, cut, fill."""
    out = {**uncertainty, "reference_m3": terms}
    for key in ("net", "cut", "fill"):
        parts = [uncertainty[key], *(terms[part][key] for part in TERMS)]
        out[key] = float(np.linalg.norm(parts))
    return out


def with_surface(vols: Volumes, sigma: np.ndarray, options: Options, grid: GridSpec) -> Volumes:
    """The volume step's result against a surface: its interval with the surface's terms
    (:data:`TERMS`; ``sigma``: the surface's per-cell error on the grid, m)."""
    u = vols.uncertainty
    cut, change = vols.cut_mask, vols.change_mask
    counted = {"net": change, "cut": cut & change, "fill": change & ~cut}
    model = {"nugget": u["nugget_m2"], "psill": u["psill_m2"], "range": u["range_m"]}
    datum = bias_sigma(u["stable_cells"], grid.cell, model, 1) if options.correction == "none" else 0.0
    z = z_value(options.lod_confidence)
    terms = design_terms(counted, sigma, options.design_uncertainty, datum, grid.cell_area, z)
    terms["truncation"] = truncation(vols.diff, counted, grid.cell_area, z)
    terms["outline"] = outline(vols.diff, counted, grid.cell_area, z)
    return replace(vols, uncertainty=with_terms(vols.uncertainty, terms))
