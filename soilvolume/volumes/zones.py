"""Per-zone volume budgets and polygon masks from a vector file (GeoPackage/Shapefile/GeoJSON).

Polygons are read with fiona when it is installed, else with GDAL's ``osgeo.ogr``; they are
reprojected to the grid's CRS with pyproj and rasterized (cell centres inside) with rasterio.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
from rasterio import features
from rasterio.transform import Affine

from ..core.types import GridSpec, SoilVolumeError
from ..inputs.crs import horizontal


@dataclass
class Polygon:
    """One feature: GeoJSON-like geometry (in ``crs_wkt``), its id and display name."""

    id: int
    name: str
    geometry: dict[str, Any]


def read_polygons(path: str | Path, name_field: str | None = None) -> tuple[list[Polygon], str | None]:
    """(polygons, CRS WKT or None) of the first layer of ``path``; non-polygon features are
    skipped. Raises SoilVolumeError naming the file when it cannot be read."""
    path = Path(path)
    if not path.exists():
        raise SoilVolumeError(f"{path}: zones file not found")
    if not (path.is_file() or path.is_dir()):  # a FIFO would block the reader for ever
        raise SoilVolumeError(f"{path}: not a regular file (a device or pipe)")
    try:
        feats, wkt = _read_fiona(path) if _has_fiona() else _read_ogr(path)
    except SoilVolumeError:
        raise
    except Exception as exc:  # driver errors come in many types
        raise SoilVolumeError(f"{path}: cannot read polygons ({exc})") from exc
    polys = []
    for i, (fid, props, geom) in enumerate(feats):
        if geom is None or geom.get("type") not in ("Polygon", "MultiPolygon"):
            continue
        polys.append(Polygon(int(fid if fid is not None else i), _name(props, name_field, i, path), geom))
    if not polys:
        raise SoilVolumeError(f"{path}: no polygon features")
    return polys, wkt


def _has_fiona() -> bool:
    try:
        import fiona  # noqa: F401
    except ImportError:
        return False
    return True


def _read_fiona(path: Path):
    import fiona

    with fiona.open(path) as src:
        wkt = src.crs_wkt or None
        feats = [
            (f.id, dict(f.properties or {}), json.loads(json.dumps(dict(f.geometry))) if f.geometry else None)
            for f in src
        ]
    return feats, wkt


def _read_ogr(path: Path):
    from osgeo import ogr

    ogr.UseExceptions()
    ds = ogr.Open(str(path))
    if ds is None or ds.GetLayerCount() == 0:
        raise SoilVolumeError(f"{path}: not a readable vector file")
    layer = ds.GetLayer(0)
    srs = layer.GetSpatialRef()
    wkt = srs.ExportToWkt() if srs is not None else None
    feats = []
    for f in layer:
        g = f.GetGeometryRef()
        feats.append((f.GetFID(), f.items(), json.loads(g.ExportToJson()) if g else None))
    return feats, wkt


def _name(props: dict, field: str | None, i: int, path: Path) -> str:
    if field:
        if field not in props:
            raise SoilVolumeError(f"{path}: no field '{field}' (fields: {', '.join(props)})")
        return str(props[field])
    for key in props:
        if key.lower() in ("name", "zone", "label"):
            return str(props[key])
    return f"zone {i + 1}"


def _transform_coords(coords: Any, fn) -> Any:
    if isinstance(coords[0], (int, float)):
        x, y = fn(coords[0], coords[1])
        return [x, y]
    return [_transform_coords(c, fn) for c in coords]


def to_grid_crs(polys: list[Polygon], src_wkt: str | None, grid: GridSpec) -> list[Polygon]:
    """Polygons reprojected to the grid's horizontal CRS (unchanged when either CRS is unknown
    or they are equal)."""
    if not src_wkt or not grid.crs_wkt:
        return polys
    src = horizontal(pyproj.CRS.from_user_input(src_wkt))
    dst = horizontal(pyproj.CRS.from_user_input(grid.crs_wkt))
    if src.equals(dst, ignore_axis_order=True):
        return polys
    tr = pyproj.Transformer.from_crs(src, dst, always_xy=True)
    return [
        Polygon(
            p.id,
            p.name,
            {"type": p.geometry["type"], "coordinates": _transform_coords(p.geometry["coordinates"], tr.transform)},
        )
        for p in polys
    ]


def _grid_transform(grid: GridSpec) -> Affine:
    """Affine of the grid in its CRS units (GridSpec.transform when it has one)."""
    t = getattr(grid, "transform", None)
    if t is not None:
        return t
    return Affine(grid.cell, 0.0, grid.xmin, 0.0, -grid.cell, grid.ymax)


def polygon_masks(polys: list[Polygon], grid: GridSpec) -> list[np.ndarray]:
    """One boolean (rows, cols) mask per polygon (cells whose centre is inside)."""
    tf = _grid_transform(grid)
    return [
        features.rasterize(
            [(p.geometry, 1)], out_shape=(grid.rows, grid.cols), transform=tf, fill=0, dtype="uint8"
        ).astype(bool)
        for p in polys
    ]


def polygons_mask(path: str | Path, grid: GridSpec) -> np.ndarray:
    """Union of the polygons of ``path`` as a (rows, cols) mask (e.g. a stable-ground mask)."""
    polys, wkt = read_polygons(path)
    masks = polygon_masks(to_grid_crs(polys, wkt, grid), grid)
    return np.logical_or.reduce(masks)


def budget(diff: np.ndarray, mask: np.ndarray, cell_area: float) -> dict[str, float]:
    """net/cut/fill (m^3; cut and fill positive, net = fill - cut) and compared area (m^2) of
    the finite cells of ``diff`` in ``mask``."""
    from .difference import budget as cell_budget

    b = cell_budget(diff, cell_area, mask)
    return {k: b[k] for k in ("net", "cut", "fill", "area_m2")}


def zone_budgets(
    diff: np.ndarray, grid: GridSpec, zones_path: str | Path, name_field: str | None = None
) -> list[dict[str, Any]]:
    """[{id, name, net, cut, fill, area_m2, zone_area_m2}] per polygon of ``zones_path``
    (overlapping zones each count their cells; ``zone_area_m2`` = cells inside the polygon)."""
    polys, wkt = read_polygons(zones_path, name_field)
    polys = to_grid_crs(polys, wkt, grid)
    out = []
    for p, mask in zip(polys, polygon_masks(polys, grid), strict=True):
        row = {"id": p.id, "name": p.name}
        row.update(budget(diff, mask, grid.cell_area))
        row["zone_area_m2"] = float(mask.sum() * grid.cell_area)
        out.append(row)
    return out


def net_half_width(area_m2: float, cell: float, uncertainty: dict[str, Any]) -> float | None:
    """± half-width (m^3, at the run's confidence) of a zone's net volume over ``area_m2`` of
    compared cells, from the run's stable-ground error model (``report["uncertainty"]``);
    None when the report has no model. Refill errors are not included."""
    from .uncertainty import region_sigma, z_value

    try:
        model = {"nugget": uncertainty["nugget_m2"], "psill": uncertainty["psill_m2"], "range": uncertainty["range_m"]}
        bias, confidence = uncertainty.get("bias_sigma_m", 0.0), uncertainty.get("confidence", 0.95)
    except (KeyError, TypeError):
        return None
    n_cells = int(round(area_m2 / (cell * cell)))
    return z_value(confidence) * region_sigma(n_cells, cell, model, bias)
