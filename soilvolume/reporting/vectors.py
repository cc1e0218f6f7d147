"""``change_areas.gpkg``, ``zones.gpkg`` (each ``--zones`` polygon in the run's CRS with its budget)
and ``zones.csv`` (each zone's net, cut and fill with their intervals, areas and flags), by pyogrio."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from ..inputs.crs import raster_wkt
from ..inputs.io import atomic_path
from ..volumes.polygons import read_polygons, to_grid_crs

CHANGE_AREAS = "change_areas.gpkg"
ZONES = "zones.gpkg"
ZONES_CSV = "zones.csv"
#: change_areas.gpkg's attributes (the GeoJSON's properties)
AREA_COLUMNS = ("id", "kind", "area_m2", "volume_m3", "mean_change_m", "extreme_change_m")
#: zones.csv's and zones.gpkg's columns, in order (intervals as their low and high ends)
_BUDGET = (f"{k}{end}_m3" for k in ("net", "cut", "fill") for end in ("", "_low", "_high"))  # net_m3, net_low_m3, ...
ZONE_COLUMNS = ("id", "name", *_BUDGET, "area_m2", "zone_area_m2", "polygon_area_m2", "outside_grid", "repaired")
TEXT = {"kind", "name"}
INTEGER = {"id", "outside_grid", "repaired"}


def write_layer(path: Path, layer: str, geoms: list, rows: list[dict], columns: tuple, wkt: str | None) -> Path:
    """One GeoPackage layer of (multi)polygons ``geoms`` with ``columns`` of ``rows`` as attributes,
    in the CRS ``wkt``; written beside ``path`` and renamed into place."""
    import shapely  # heavy, like pyogrio (its own GDAL): loaded by the step that writes a GeoPackage
    from pyogrio import raw

    with atomic_path(path) as part:
        raw.write(
            str(part),
            geometry=shapely.to_wkb(geoms) if geoms else np.array([], dtype=object),
            field_data=[_column(rows, k) for k in columns],
            fields=list(columns),
            layer=layer,
            driver="GPKG",
            geometry_type="MultiPolygon",
            crs=wkt or None,
            promote_to_multi=True,
        )
    return path


def _column(rows: list[dict], key: str) -> np.ndarray:
    """One attribute as pyogrio takes it: text, integers, or floats (None as NaN)."""
    if key in TEXT:
        return np.array([str(r[key]) for r in rows], dtype=object)
    if key in INTEGER:
        return np.array([int(r[key]) for r in rows], dtype=np.int64)
    return np.array([np.nan if r[key] is None else float(r[key]) for r in rows], dtype=np.float64)


def write_change_area_gpkg(folder: Path, feats: list[dict], wkt: str | None) -> Path:
    """``change_areas.gpkg`` (layer ``change_areas``) of the GeoJSON features ``feats``."""
    from shapely.geometry import shape  # heavy: only a run writing a GeoPackage loads it

    geoms = [shape(f["geometry"]) for f in feats]
    rows = [f["properties"] for f in feats]
    return write_layer(folder / CHANGE_AREAS, "change_areas", geoms, rows, AREA_COLUMNS, wkt)


def zone_row(zone: dict) -> dict:
    """One row of :data:`ZONE_COLUMNS` from report.json's ``zones`` item (no interval: empty)."""
    pm = zone.get("uncertainty_m3") or {}
    row = {"id": zone["id"], "name": zone["name"], "area_m2": zone["area_m2"]}
    for part in ("net", "cut", "fill"):
        value, half = zone[part], pm.get(part)
        row[f"{part}_m3"] = value
        row[f"{part}_low_m3"] = None if half is None else value - half
        row[f"{part}_high_m3"] = None if half is None else value + half
    for key in ("zone_area_m2", "polygon_area_m2", "outside_grid", "repaired"):
        row[key] = zone.get(key)
    return row


def write_zones(
    folder: Path, zones: list[dict], zones_path: str | Path, grid: GridSpec, gpkg: bool = False
) -> list[str]:
    """``zones.csv`` of report.json's ``zones`` and with ``gpkg`` ``zones.gpkg`` (layer ``zones``: each
    polygon of ``zones_path`` in the grid's CRS, as the budgets were measured); returns their names."""
    rows = [zone_row(z) for z in zones]
    if gpkg:
        polys, wkt = read_polygons(zones_path)
        polys = to_grid_crs(polys, wkt, grid, zones_path)
        write_layer(folder / ZONES, "zones", [p.geometry for p in polys], rows, ZONE_COLUMNS, raster_wkt(grid.crs_wkt))
    with atomic_path(folder / ZONES_CSV) as part, open(part, "w", newline="", encoding="utf-8") as f:
        out = csv.DictWriter(f, fieldnames=ZONE_COLUMNS)
        out.writeheader()
        for row in rows:
            out.writerow({k: "" if v is None else (int(v) if isinstance(v, bool) else v) for k, v in row.items()})
    return [ZONES, ZONES_CSV] if gpkg else [ZONES_CSV]
