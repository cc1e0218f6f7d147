"""Polygons (and lines) of a user's vector file: read with pyogrio (its own GDAL), invalid geometries
repaired with shapely's ``make_valid`` (refused without area), brought into the grid's CRS with
pyproj (a file without a CRS is taken to be in the grid's; coordinates its CRS cannot hold refused)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import SoilVolumeError, short_error
from ..inputs.crs import horizontal

POLYGONAL = ("Polygon", "MultiPolygon")


@dataclass
class Polygon:
    """One feature: its id, display name, shapely geometry and whether it was repaired."""

    id: int
    name: str
    geometry: Any
    repaired: bool = False


def read_polygons(
    path: str | Path, name_field: str | None = None, what: str = "zones file"
) -> tuple[list[Polygon], str | None]:
    """(polygons, CRS WKT or None) of ``path``'s first layer; an error naming ``what`` and the file if unusable."""
    path = Path(path)
    feats, wkt = _features(path, what, "polygons", POLYGONAL)
    if not feats:
        raise SoilVolumeError(f"{path}: no polygon features in this {what}")
    fields = feats[0][2]  # one layer's: every feature's
    if name_field and name_field not in fields:
        raise SoilVolumeError(f"{path}: no field '{name_field}' (fields: {', '.join(fields)})")
    key = name_field or next((k for k in fields if k.lower() in ("name", "zone", "label")), None)
    return [_valid(Polygon(fid, str(p[key]) if key else f"zone {i + 1}", g), path) for i, fid, p, g in feats], wkt


def _features(path: Path, what: str, noun: str, kinds: tuple[str, ...]) -> tuple[list[tuple], str | None]:
    """([(index, id, attributes, geometry)] of the ``kinds`` features, CRS WKT); a failure one line naming the file."""
    if not path.exists():
        raise SoilVolumeError(f"{path}: {what} not found")
    if not (path.is_file() or path.is_dir()):  # a FIFO would block the reader for ever
        raise SoilVolumeError(f"{path}: not a regular file (a device or pipe)")
    try:
        import pyproj  # the file's CRS
        import shapely  # validity and repair
        from pyogrio import raw  # the reader
    except ImportError as exc:
        raise SoilVolumeError(f"{path}: reading {noun} needs {exc.name} (pip install {exc.name})") from None
    try:
        with warnings.catch_warnings():  # GDAL's and GEOS's complaints about a broken file: the error says it
            warnings.simplefilter("ignore")
            meta, fids, wkb, values = raw.read(str(path), return_fids=True)
            geoms = shapely.from_wkb(wkb) if wkb is not None else [None] * len(fids)
        wkt = pyproj.CRS.from_user_input(meta["crs"]).to_wkt() if meta.get("crs") else None
    except Exception as exc:  # noqa: BLE001 - driver errors come in many types
        raise SoilVolumeError(f"{path}: cannot read {noun} from this {what} ({short_error(exc)})") from None
    return [
        (i, int(fid), {n: v[i] for n, v in zip(meta["fields"], values, strict=True)}, g)
        for i, (fid, g) in enumerate(zip(fids, geoms, strict=True))
        if g is not None and g.geom_type in kinds and not g.is_empty
    ], wkt


def feature_fields(path: str | Path) -> list[tuple[int, dict[str, Any]]]:
    """[(feature id, attributes)] of the polygon features of ``path`` (as :func:`read_polygons`)."""
    return [(fid, props) for _, fid, props, _ in _features(Path(path), "zones file", "polygons", POLYGONAL)[0]]


def _valid(p: Polygon, path: Path) -> Polygon:
    """``p`` with finite coordinates and a valid polygonal geometry (repaired), or an error."""
    import shapely

    if not np.isfinite(shapely.get_coordinates(p.geometry)).all():  # GEOS cannot even repair it
        raise SoilVolumeError(f"{path}: '{p.name}' has a coordinate that is not a number (NaN or infinite)")
    if shapely.is_valid(p.geometry):
        return p
    try:
        fixed = shapely.make_valid(p.geometry)
    except shapely.errors.GEOSException as exc:
        raise SoilVolumeError(f"{path}: '{p.name}' is not a valid polygon and cannot be repaired ({exc})") from None
    parts = [g for g in shapely.get_parts(fixed) if g.geom_type in POLYGONAL]
    area = shapely.union_all(parts) if parts else None
    if area is None or area.is_empty or area.area <= 0:
        raise SoilVolumeError(f"{path}: '{p.name}' is not a valid polygon and has no area once repaired")
    return Polygon(p.id, p.name, area, repaired=True)


def grid_transform(src_wkt: str | None, grid_wkt: str | None):
    """The Transformer between a file's and a grid's horizontal CRSs; None if either is unknown or they are equal."""
    import pyproj

    if not src_wkt or not grid_wkt:
        return None
    src, dst = (horizontal(pyproj.CRS.from_user_input(w)) for w in (src_wkt, grid_wkt))
    return None if src.equals(dst, ignore_axis_order=True) else pyproj.Transformer.from_crs(src, dst, always_xy=True)


def to_grid_crs(polys: list[Polygon], src_wkt: str | None, grid, path: str | Path = "") -> list[Polygon]:
    """Polygons in the grid's horizontal CRS; coordinates that cannot be moved an error naming the file."""
    import pyproj
    import shapely

    tr = grid_transform(src_wkt, grid.crs_wkt)
    if tr is None:
        return polys
    out = []
    for p in polys:
        geom = shapely.transform(p.geometry, lambda xy: np.column_stack(tr.transform(xy[:, 0], xy[:, 1])))
        if not np.isfinite(shapely.get_coordinates(geom)).all():
            src, dst = (horizontal(pyproj.CRS.from_user_input(w)) for w in (src_wkt, grid.crs_wkt))
            raise SoilVolumeError(
                f"{path}: '{p.name}' cannot be brought from {src.name} into the survey's {dst.name} "
                "(are its coordinates really in the CRS the file declares?)"
            )
        out.append(Polygon(p.id, p.name, geom, p.repaired))
    return out


def read_lines(path: str | Path, what: str = "sections file") -> tuple[list[Polygon], str | None]:
    """(lines named by a field name, id or label, CRS WKT or None) of ``path``'s first layer; an error if unusable."""
    import shapely

    path = Path(path)
    feats, wkt = _features(path, what, "lines", ("LineString", "MultiLineString"))
    lines = []
    for i, fid, props, geom in feats:
        if not np.isfinite(shapely.get_coordinates(geom)).all():
            raise SoilVolumeError(f"{path}: line {i + 1} has a coordinate that is not a number")
        key = next((k for k in props if k.lower() in ("name", "id", "label")), None)
        name = str(props[key]) if key and props[key] is not None else f"line {i + 1}"
        lines.append(Polygon(fid, name, geom))
    if not lines:
        raise SoilVolumeError(f"{path}: no line features in this {what}")
    return lines, wkt
