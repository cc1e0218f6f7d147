"""Words and tables of report.html: numbers formatted for reading, report keys as words, and the
:class:`Table` the templates lay out (cells are plain text; the template escapes them)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

LABELS = {  # report keys -> words (units in brackets)
    "net": "net (m³)",
    "cut": "cut (m³)",
    "fill": "fill (m³)",
    "net_compared_area": "net, all compared cells (m³)",
    "net_all_cells": "net, every compared cell (m³)",
    "net_change_areas": "net, change areas (m³)",
    "confidence": "confidence level",
    "sigma_m": "noise on stable ground, NMAD (m)",
    "lod_m": "level of detection (m)",
    "nugget_m2": "uncorrelated error variance (m²)",
    "psill_m2": "spatially correlated error variance (m²)",
    "range_m": "correlation range (m)",
    "bias_sigma_m": "error of the correction's level, 1σ (m)",
    "interpolated_m3": "interpolated volume (m³)",
    "refill_sigma_m3": "refill error, 1σ (m³)",
    "stable_cells": "stable-ground cells",
    "change_area_m2": "detected change area (m²)",
    "filled_cells": "refilled cells",
    "filled_area_m2": "refilled area (m²)",
    "filled_net_m3": "net volume in refilled cells (m³)",
    "mean": "mean (m)",
    "std": "standard deviation (m)",
    "nmad": "NMAD (m)",
    "rmse": "RMSE (m)",
    "n_cells": "cells",
    "crop": "reading and cropping",
    "read": "reading",
    "coarse": "coarse registration",
    "fine": "fine registration",
    "register_other": "registration, other",
    "grids": "gridding",
    "planes": "reference planes",
    "volume": "volumes and uncertainty",
    "write": "writing rasters",
}
UNIT_WORDS = {"m": "m", "m2": "m²", "m3": "m³", "deg": "°", "s": "s"}


@dataclass(frozen=True)
class Table:
    """A table of the page: its header and rows of plain-text cells; the first column left-aligned
    when ``first_left``."""

    head: list[str]
    rows: list[list[str]]
    first_left: bool = True


def get(d: Any, *keys: str, default: Any = None) -> Any:
    """``d[k1][k2]...``, or ``default`` where a level is missing or not a dict."""
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def fmt(v: Any, digits: int = 2) -> str:
    """A value for reading: thousands separated, ``digits`` decimals, yes/no, "–" for none."""
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}"
    if isinstance(v, (float, np.floating)):
        return "–" if not math.isfinite(float(v)) else f"{float(v):,.{digits}f}"
    return str(v)


def pm(value: Any, half: Any) -> str:
    """``value ± half`` (no ± without a half-width)."""
    return fmt(value) + (f" ± {fmt(half)}" if isinstance(half, (int, float)) else "")


def label(key: str) -> str:
    """Words for a report key: from LABELS, else the key with its unit suffix in brackets."""
    if key in LABELS:
        return LABELS[key]
    head, _, unit = key.rpartition("_")
    if head and unit in UNIT_WORDS:
        return f"{head.replace('_', ' ')} ({UNIT_WORDS[unit]})"
    return key.replace("_", " ")


def kv(d: Any, digits: int = 4) -> Table | None:
    """A dict of report values as a two-column table; None when there is none."""
    if not isinstance(d, dict) or not d:
        return None
    rows = [[label(str(k)), str(v)[:300] if isinstance(v, (list, dict)) else fmt(v, digits)] for k, v in d.items()]
    return Table(["", "value"], rows)
