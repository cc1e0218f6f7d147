"""The vector outputs. ``change_areas.geojson`` (and ``.gpkg``): each connected patch of significant
cut or fill (the cells the headline sums) as one polygon with its kind, area and volume, outlined on
report.html's map; tile by tile, they are drawn on the overview grid the map shows, and their volumes
are that grid's. ``zones.gpkg`` (each ``--zones`` polygon in the run's CRS with its budget) and
``zones.csv`` (each zone's net, cut and fill with their intervals, areas and flags). GeoPackages by pyogrio."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from ..inputs.crs import raster_wkt
from ..inputs.io import atomic_path
from ..volumes.polygons import read_polygons, to_grid_crs

FILE = "change_areas.geojson"
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


def zone_row(zone: dict) -> dict:
    """One row of :data:`ZONE_COLUMNS` from report.json's ``zones`` item (no interval: empty)."""
    pm = zone.get("uncertainty_m3") or {}
    row = {k: zone.get(k) for k in ZONE_COLUMNS if not k.endswith("_m3")}  # id, name, areas and flags
    for part in ("net", "cut", "fill"):
        value, half = zone[part], pm.get(part)
        row[f"{part}_m3"] = value
        row[f"{part}_low_m3"] = None if half is None else value - half
        row[f"{part}_high_m3"] = None if half is None else value + half
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


def patches(change: np.ndarray, cut: np.ndarray) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """(labels, [(kind, label), ...]): 4-connected patches of the cut areas (``cut``) and of the fill
    areas (the rest of ``change``), as the headline sums them; label 0 = no patch."""
    from scipy import ndimage

    labels = np.zeros(change.shape, np.int32)
    kinds: list[tuple[str, int]] = []
    for kind, cells in (("cut", change & cut), ("fill", change & ~cut)):
        lab, n = ndimage.label(cells)
        labels[cells] = lab[cells] + len(kinds)
        kinds += [(kind, len(kinds) + i + 1) for i in range(n)]
    return labels, kinds


def features(diff: np.ndarray, change: np.ndarray, cut: np.ndarray, grid: GridSpec) -> list[dict]:
    """GeoJSON features (CRS units of the grid) of every patch: kind, area_m2, volume_m3 (cut
    as a positive number, as the headline), mean and extreme change (m)."""
    from rasterio import features as rfeatures

    labels, kinds = patches(change, cut)
    if not kinds:
        return []
    d = np.nan_to_num(np.asarray(diff, dtype=float))
    index = np.arange(1, len(kinds) + 1)
    from scipy import ndimage

    sums = ndimage.sum(d, labels, index)
    counts = ndimage.sum(np.ones_like(d), labels, index)
    lows, highs = ndimage.minimum(d, labels, index), ndimage.maximum(d, labels, index)
    shapes = {int(v): g for g, v in rfeatures.shapes(labels, mask=labels > 0, connectivity=4, transform=grid.transform)}
    out = []
    for (kind, label), total, n, lo, hi in zip(kinds, sums, counts, lows, highs, strict=True):
        sign = -1.0 if kind == "cut" else 1.0
        props = {
            "id": label,
            "kind": kind,
            "area_m2": round(float(n) * grid.cell_area, 3),
            "volume_m3": round(sign * float(total) * grid.cell_area, 3) + 0.0,
            "mean_change_m": round(float(total) / float(n), 4),
            "extreme_change_m": round(float(lo if kind == "cut" else hi), 4),
        }
        out.append({"type": "Feature", "properties": props, "geometry": shapes[label]})
    return out


def write_change_areas(
    path: str | Path, diff: np.ndarray, change: np.ndarray, cut: np.ndarray, grid: GridSpec, gpkg: bool = False
) -> dict:
    """Write the polygons (GeoJSON naming the grid's horizontal CRS; with ``gpkg`` also
    change_areas.gpkg); returns {"file", "cut_polygons", "fill_polygons", "cut_m3", "fill_m3"}."""
    path = Path(path)
    feats = features(diff, change, cut, grid)
    crs = {"type": "name", "properties": {"name": _crs_name(raster_wkt(grid.crs_wkt))}}
    doc = {"type": "FeatureCollection", "name": "change_areas", "crs": crs, "features": feats}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc), encoding="utf-8")
    if gpkg:  # change_areas.gpkg, layer change_areas
        from shapely.geometry import shape  # heavy: only a run writing a GeoPackage loads it

        geoms, rows = [shape(f["geometry"]) for f in feats], [f["properties"] for f in feats]
        write_layer(path.parent / CHANGE_AREAS, "change_areas", geoms, rows, AREA_COLUMNS, raster_wkt(grid.crs_wkt))
    by = {k: [f["properties"]["volume_m3"] for f in feats if f["properties"]["kind"] == k] for k in ("cut", "fill")}
    polygons = {f"{k}_polygons": len(v) for k, v in by.items()}
    return {"file": path.name, **polygons, **{f"{k}_m3": float(sum(v)) for k, v in by.items()}}


def _crs_name(wkt: str | None) -> str:
    """An OGC URN for an EPSG CRS (what GeoJSON readers understand), else the WKT itself."""
    if not wkt:
        return ""
    import pyproj

    crs = pyproj.CRS.from_user_input(wkt)
    code = crs.to_epsg(min_confidence=70)
    return f"urn:ogc:def:crs:EPSG::{code}" if code else crs.to_wkt()
