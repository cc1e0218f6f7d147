"""Toe polygons from any OGR vector file (GeoPackage, Shapefile, GeoJSON, ...) read with
pyogrio (a runtime dependency), each with its name and density fields when named, and moved into
a survey grid's local frame. Bad files and polygons are refused in one line naming the file."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import shapely
from pyogrio import raw

from ..core.types import GridSpec, short_error
from ..volumes.polygons import grid_transform
from .types import Pile, PileError, checked_density, checked_polygon

NAME_FIELDS = ("name", "pile", "label", "id")  # a name field found without one given


def read_piles(path: str | Path, name_field: str | None = None, density_field: str | None = None) -> tuple:
    """([:class:`Pile`] in the file's coordinates, the file's CRS WKT or None) of the first layer
    of ``path``: every polygon feature, named by ``name_field`` (else a field called like
    :data:`NAME_FIELDS`, else its feature id), its density from ``density_field``."""
    path = Path(path)
    if not path.is_file() and not path.is_dir():
        raise PileError(f"{path}: piles file not found")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meta, fids, wkb, values = raw.read(str(path), return_fids=True)
    except Exception as exc:  # noqa: BLE001 - GDAL's errors come in many types
        raise PileError(f"{path}: cannot read polygons from it ({short_error(exc)})") from None
    fields = {str(n): v for n, v in zip(meta["fields"], values, strict=True)}
    for wanted in (name_field, density_field):
        if wanted and wanted not in fields:
            raise PileError(f"{path}: no field '{wanted}' (fields: {', '.join(fields) or 'none'})")
    name_field = name_field or next((f for f in fields if f.lower() in NAME_FIELDS), None)
    geoms = shapely.from_wkb(wkb) if wkb is not None else [None] * len(fids)
    piles = [_pile(path, int(fid), k, geoms[k], fields, name_field, density_field) for k, fid in enumerate(fids)]
    piles = [p for p in piles if p is not None]
    if not piles:
        raise PileError(f"{path}: no polygon features in it")
    return piles, meta.get("crs")


def _pile(path: Path, fid: int, k: int, geom, fields: dict, name_field, density_field) -> Pile | None:
    """Feature ``k`` as a :class:`Pile` (None when it is not a polygon); a bad polygon or
    density is an error naming the file and the feature."""
    if geom is not None and geom.geom_type not in ("Polygon", "MultiPolygon"):
        return None
    name = str(fields[name_field][k]) if name_field and fields[name_field][k] is not None else f"feature {fid}"
    density = fields[density_field][k] if density_field else None
    if density is not None and isinstance(density, float) and np.isnan(density):
        density = None
    try:
        checked_polygon(geom, name)
        density = checked_density(density, name)
    except PileError as exc:
        raise PileError(f"{path}: {exc}") from None
    return Pile(geom, name, density)


def local_piles(piles: list[Pile], crs_wkt: str | None, grid: GridSpec) -> list[Pile]:
    """``piles`` (in CRS ``crs_wkt``; None: the grid's) in the grid's local frame (metres from its
    origin), reprojected with pyproj when the two CRSs differ."""
    shift = np.array(grid.origin[:2])
    project = grid_transform(crs_wkt, grid.crs_wkt)

    def move(xy: np.ndarray) -> np.ndarray:
        if project is not None:
            xy = np.column_stack(project.transform(xy[:, 0], xy[:, 1]))
        return xy * grid.xy_unit - shift

    out = [Pile(shapely.transform(p.polygon, move), p.name, p.density) for p in piles]
    for p in out:
        if not np.isfinite(shapely.get_coordinates(p.polygon)).all():
            raise PileError(f"pile '{p.name}': its polygon cannot be brought into the survey's CRS")
    return out
