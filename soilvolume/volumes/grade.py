"""Progress against a design, overall and per zone: each cell's class by a tolerance ``T`` (cut to go
above it, on grade within ±T, fill to go below), the share on grade and the cut and fill to go (m^3:
the whole survey - design depth over those cells, not only its part beyond ``T``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import GridSpec
from .zones import on_grid, polygon_masks

CUT, ON_GRADE, FILL = 1, 2, 3  # grade.tif's classes (255: not compared)
CLASSES = {"1": "cut to go: survey above design by more than T", "2": "on grade: within ±T", "3": "fill to go"}


def classes(diff: np.ndarray, tolerance: float) -> np.ndarray:
    """Each cell's class (float: NaN where ``diff``, survey - design, is not finite)."""
    ok = np.isfinite(diff)
    return np.select([ok & (diff > tolerance), ok & (diff < -tolerance), ok], [CUT, FILL, ON_GRADE], np.nan)


def summary(diff: np.ndarray, cls: np.ndarray, cell_area: float, mask: np.ndarray | None = None) -> dict[str, Any]:
    """The compared area (m^2), its share on grade, the cut and fill to go (m^3), over ``mask`` when given."""
    inside = np.isfinite(cls) if mask is None else np.isfinite(cls) & mask
    n = int(inside.sum())
    cut, fill = inside & (cls == CUT), inside & (cls == FILL)
    return {
        "compared_area_m2": n * cell_area,
        "on_grade_share": float((inside & (cls == ON_GRADE)).sum() / n) if n else None,
        "on_grade_area_m2": float((inside & (cls == ON_GRADE)).sum() * cell_area),
        "cut_to_go_m3": float(diff[cut].sum() * cell_area),
        "fill_to_go_m3": float(-diff[fill].sum() * cell_area),
        "cut_to_go_area_m2": float(cut.sum() * cell_area),
        "fill_to_go_area_m2": float(fill.sum() * cell_area),
    }


def grade(diff: np.ndarray, grid: GridSpec, tolerance: float, zones: str | Path | None) -> tuple[np.ndarray, dict]:
    """(the class grid, report.json's ``grade``: tolerance, classes, the :func:`summary` and each zone's)."""
    cls = classes(diff, tolerance)
    out = {"tolerance_m": tolerance, "classes": CLASSES, **summary(diff, cls, grid.cell_area)}
    if zones:
        polys, _ = on_grid(zones, grid)
        out["zones"] = [
            {"id": p.id, "name": p.name, **summary(diff, cls, grid.cell_area, m)}
            for p, m in zip(polys, polygon_masks(polys, grid), strict=True)
        ]
    return cls, out


def progress(start: dict, end: dict) -> dict:
    """A period's progress between the :func:`grade` summaries at its start and end: the cut and fill
    done (m^3), the area brought on grade (m^2), at its end the share on grade and what is to go; per zone."""
    out = {f"{k}_done_m3": start[f"{k}_to_go_m3"] - end[f"{k}_to_go_m3"] for k in ("cut", "fill")}
    out["on_grade_gained_m2"] = end["on_grade_area_m2"] - start["on_grade_area_m2"]
    out.update({k: end[k] for k in ("on_grade_share", "cut_to_go_m3", "fill_to_go_m3")})
    if "zones" in start:
        pairs = zip(start["zones"], end["zones"], strict=True)
        out["zones"] = [{"id": a["id"], "name": a["name"], **progress(a, b)} for a, b in pairs]
    return out
