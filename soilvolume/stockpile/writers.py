"""The stockpile inventory's outputs: ``piles`` rows for report.json, ``piles.csv`` and
``piles.gpkg`` (the polygons with the same attributes, in the survey's CRS, written by pyogrio,
a runtime dependency). Each file is written beside its destination and renamed into place."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np
import shapely
from pyogrio import raw

from ..core.types import GridSpec
from .types import Inventory, PileVolume

#: piles.csv's and piles.gpkg's columns, in order (intervals as their low and high ends)
COLUMNS = (
    "name",
    "base",
    "volume_m3",
    "interval_low_m3",
    "interval_high_m3",
    "fill_m3",
    "cut_m3",
    "area_m2",
    "max_height_m",
    "base_spread_m3",
    "toe_rise_m",
    "density_t_m3",
    "tonnes",
    "tonnes_low",
    "tonnes_high",
    "warnings",
)
TEXT = {"name", "base", "warnings"}


def _r(value: float | None, digits: int = 3) -> float | None:
    """``value`` rounded for the outputs (None stays None)."""
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def pile_row(p: PileVolume) -> dict:
    """One pile as report.json's ``piles`` item."""
    return {
        "name": p.name,
        "base": p.base,
        "volume_m3": _r(p.volume_m3),
        "interval_m3": [_r(p.interval_m3[0]), _r(p.interval_m3[1])],
        "fill_m3": _r(p.fill_m3),
        "cut_m3": _r(p.cut_m3),
        "area_m2": _r(p.area_m2),
        "max_height_m": _r(p.max_height_m),
        "base_spread_m3": _r(p.base_spread_m3),
        "by_base_m3": {k: _r(v) for k, v in p.by_base_m3.items()},
        "toe_rise_m": _r(p.toe_rise_m),
        "empty_share": _r(p.empty_share, 4),
        "density_t_m3": p.density,
        "tonnes": _r(p.tonnes),
        "tonnes_interval": None if p.tonnes_interval is None else [_r(t) for t in p.tonnes_interval],
        "warnings": list(p.warnings),
    }


def report_piles(inventory: Inventory) -> list[dict]:
    """report.json's ``piles`` list."""
    return [pile_row(p) for p in inventory.piles]


def flat_row(p: PileVolume) -> dict:
    """One pile as a row of :data:`COLUMNS` (piles.csv, piles.gpkg)."""
    row = pile_row(p)
    lo, hi = row.pop("interval_m3")
    t_lo, t_hi = row.pop("tonnes_interval") or (None, None)
    row.update(interval_low_m3=lo, interval_high_m3=hi, tonnes_low=t_lo, tonnes_high=t_hi)
    row["warnings"] = "; ".join(p.warnings)
    return {k: row[k] for k in COLUMNS}


def write_csv(path: str | Path, inventory: Inventory) -> Path:
    """``piles.csv``: one row per pile (:data:`COLUMNS`; empty where there is no density)."""
    path = Path(path)
    part = path.with_name(f".{path.name}.part")
    with open(part, "w", newline="", encoding="utf-8") as f:
        out = csv.DictWriter(f, fieldnames=COLUMNS)
        out.writeheader()
        for p in inventory.piles:
            out.writerow({k: "" if v is None else v for k, v in flat_row(p).items()})
    os.replace(part, path)
    return path


def write_gpkg(path: str | Path, inventory: Inventory, grid: GridSpec) -> Path:
    """``piles.gpkg``: layer ``piles``, each pile's polygon in the grid's CRS (the local frame
    moved by the grid's origin, in the CRS's units) with :data:`COLUMNS` as attributes."""
    path = Path(path)
    part = path.with_name(f".{path.name}.part.gpkg")
    rows = [flat_row(p) for p in inventory.piles]
    geoms = [_absolute(p.polygon, grid) for p in inventory.piles]
    fields = [
        np.array([r[k] or "" for r in rows], dtype=object)
        if k in TEXT
        else np.array([np.nan if r[k] is None else r[k] for r in rows], dtype=np.float64)
        for k in COLUMNS
    ]
    part.unlink(missing_ok=True)
    raw.write(
        str(part),
        geometry=shapely.to_wkb(geoms),
        field_data=fields,
        fields=list(COLUMNS),
        layer="piles",
        driver="GPKG",
        geometry_type="MultiPolygon",
        crs=grid.crs_wkt,
        promote_to_multi=True,
    )
    os.replace(part, path)
    return path


def _absolute(polygon, grid: GridSpec):
    """``polygon`` (local m) in the grid's CRS units."""
    ox, oy = grid.origin[0], grid.origin[1]
    return shapely.transform(polygon, lambda xy: (xy + np.array([ox, oy])) / grid.xy_unit)
