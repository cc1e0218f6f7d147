"""Each connected patch of significant cut or fill (the cells the headline sums) as one polygon with
its kind, area and volume: ``change_areas.geojson`` (and ``.gpkg``), outlined on report.html's map.
Tile by tile, they are drawn on the overview grid the map shows, and their volumes are that grid's."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from ..inputs.crs import raster_wkt
from ..inputs.io import atomic_path
from .vectors import write_change_area_gpkg

FILE = "change_areas.geojson"


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
    if gpkg:
        write_change_area_gpkg(path.parent, feats, raster_wkt(grid.crs_wkt))
    by = {k: [f["properties"]["volume_m3"] for f in feats if f["properties"]["kind"] == k] for k in ("cut", "fill")}
    return {
        "file": path.name,
        "cut_polygons": len(by["cut"]),
        "fill_polygons": len(by["fill"]),
        "cut_m3": float(sum(by["cut"])),
        "fill_m3": float(sum(by["fill"])),
    }


def _crs_name(wkt: str | None) -> str:
    """An OGC URN for an EPSG CRS (what GeoJSON readers understand), else the WKT itself."""
    import pyproj

    if not wkt:
        return ""
    crs = pyproj.CRS.from_user_input(wkt)
    code = crs.to_epsg(min_confidence=70)
    return f"urn:ogc:def:crs:EPSG::{code}" if code else crs.to_wkt()
