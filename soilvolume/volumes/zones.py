"""Per-zone volume budgets and polygon masks from a vector file (GeoPackage/Shapefile/GeoJSON).

Polygons are read, repaired and brought into the grid's CRS by :mod:`polygons`, and rasterized
(cell centres inside) with rasterio. A zone with no cell centre on the grid (outside the survey,
or in the wrong CRS) is flagged, never a silent 0 m3; when no zone meets the grid the run fails.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import GridSpec, SoilVolumeError
from .difference import budget as cell_budget
from .difference import signed_budget
from .polygons import Polygon, read_polygons, to_grid_crs
from .uncertainty import TERMS, widen, z_value

# The grid's transform is given, yet GDAL's scratch raster inside rasterize warns all the same. A
# filter for the process, not ``catch_warnings``: that swaps the global filter list and is not
# thread-safe (tile tasks run on threads; a neighbour's exit let the warning reach stderr).
warnings.filterwarnings("ignore", message="Dataset has no geotransform", module="rasterio.features")


def _grid_transform(grid: GridSpec):
    """Affine of the grid in its CRS units (GridSpec.transform when it has one)."""
    from rasterio.transform import Affine  # rasterio imported when zones are used

    t = getattr(grid, "transform", None)
    if t is not None:
        return t
    return Affine(grid.cell, 0.0, grid.xmin, 0.0, -grid.cell, grid.ymax)


def polygon_masks(polys: list[Polygon], grid: GridSpec) -> list[np.ndarray]:
    """One boolean (rows, cols) mask per polygon (cells whose centre is inside)."""
    from rasterio import features

    tf = _grid_transform(grid)
    return [
        features.rasterize(
            [(p.geometry, 1)], out_shape=(grid.rows, grid.cols), transform=tf, fill=0, dtype="uint8"
        ).astype(bool)
        for p in polys
    ]


def polygons_mask(path: str | Path, grid: GridSpec, what: str = "{opt:stable_mask} file") -> np.ndarray:
    """Union of the polygons of ``path`` as a (rows, cols) mask (e.g. a stable-ground mask); one
    that covers no cell of the grid is an error naming the file."""
    polys, wkt = read_polygons(path, what=what)
    polys = to_grid_crs(polys, wkt, grid, path)
    if not any(_meets(p, grid) for p in polys):
        raise SoilVolumeError(f"{path}: no polygon of this {what} meets the survey's grid{_crs_hint(wkt)}")
    return np.logical_or.reduce(polygon_masks(polys, grid))


def _meets(p: Polygon, grid: GridSpec) -> bool:
    """Whether the polygon's bounds meet the grid's extent (both in the grid's CRS units)."""
    u = grid.xy_unit
    x0, y0, x1, y1 = p.geometry.bounds
    gx0, gy1 = grid.xmin / u, grid.ymax / u
    gx1, gy0 = gx0 + grid.cols * grid.cell / u, gy1 - grid.rows * grid.cell / u
    return x0 <= gx1 and gx0 <= x1 and y0 <= gy1 and gy0 <= y1


def _crs_hint(wkt: str | None) -> str:
    return " (the file has no CRS: is it in the survey's?)" if not wkt else " (is its CRS right?)"


def budget(diff: np.ndarray, mask: np.ndarray, cell_area: float) -> dict[str, float]:
    """net/cut/fill (m^3; cut and fill positive, net = fill - cut) and compared area (m^2) of
    the finite cells of ``diff`` in ``mask``."""
    b = cell_budget(diff, cell_area, mask)
    return {k: b[k] for k in ("net", "cut", "fill", "area_m2")}


def zone_budgets(
    diff: np.ndarray,
    grid: GridSpec,
    zones_path: str | Path,
    name_field: str | None = None,
    whole: bool = True,
    interval: Callable[[np.ndarray], dict[str, float]] | None = None,
    areas: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[dict[str, Any]]:
    """[{id, name, net, cut, fill, area_m2, zone_area_m2, polygon_area_m2, repaired}] per polygon
    of ``zones_path`` (overlapping zones each count their cells; ``zone_area_m2`` = grid cells
    inside the polygon); on the ``whole`` grid (not a tile's window), see :func:`check_inside`.
    ``interval``: a zone's ± (net, cut, fill) from its mask (:func:`zone_interval`), kept as
    ``uncertainty_m3``. ``areas``: the (fill, cut) areas a zone's fill and cut are summed over,
    as the headline's (else by each cell's sign: noise in a pile's buffer would be cut)."""
    polys, wkt = read_polygons(zones_path, name_field)
    polys = to_grid_crs(polys, wkt, grid, zones_path)
    out = []
    for p, mask in zip(polys, polygon_masks(polys, grid), strict=True):
        row = {"id": p.id, "name": p.name}
        row.update(budget(diff, mask, grid.cell_area))
        if areas is not None:
            split = signed_budget(diff, areas[0] & mask, areas[1] & mask, grid.cell_area)
            row.update(cut=split["cut"], fill=split["fill"], net=split["fill"] - split["cut"])
        row["zone_area_m2"] = float(mask.sum() * grid.cell_area)
        row["polygon_area_m2"] = float(p.geometry.area * grid.xy_unit**2)
        row["repaired"] = p.repaired
        if interval is not None:
            row["uncertainty_m3"] = interval(mask)
        out.append(row)
    return check_inside(out, zones_path, wkt) if whole else out


def check_inside(rows: list[dict[str, Any]], path: str | Path, wkt: str | None = "") -> list[dict[str, Any]]:
    """Flag the zones with no cell of the grid (``outside_grid``); an error when none has one."""
    for row in rows:
        row["outside_grid"] = row["zone_area_m2"] <= 0
    if rows and all(r["outside_grid"] for r in rows):
        raise SoilVolumeError(f"{path}: no zone meets the survey's grid{_crs_hint(wkt)}")
    return rows


def zone_messages(rows: list[dict[str, Any]]) -> list[str]:
    """Sentences for the quality verdict about zones that lie outside the grid, in part or whole,
    or whose geometry was repaired."""
    out = []
    outside = [r["name"] for r in rows if r.get("outside_grid")]
    if outside:
        out.append(
            "zones without a grid cell centre inside (outside the survey, in another CRS than declared, or "
            f"smaller than a cell): their volumes are not measured: {_names(outside)}"
        )
    part = [r["name"] for r in rows if not r.get("outside_grid") and r["zone_area_m2"] < 0.9 * r["polygon_area_m2"]]
    if part:
        out.append(f"zones only partly on the surveyed grid (their volumes cover that part): {_names(part)}")
    fixed = [r["name"] for r in rows if r.get("repaired")]
    if fixed:
        out.append(f"zones whose invalid geometry (e.g. self-intersecting) was repaired: {_names(fixed)}")
    return out


def _names(names: list[str], limit: int = 5) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def zone_interval(model: Callable[..., dict], region: np.ndarray, headline: dict, zone: np.ndarray) -> dict[str, float]:
    """A zone's ± half-widths (m^3, net/cut/fill at the run's confidence): the run's error model
    (``model``: :func:`~.uncertainty.volume_uncertainty` with the run's arguments) over the cells
    of ``region`` (the headline's change areas) inside ``zone``; the headline's further terms
    (registration, small detections, classification, cell statistic: ``headline["terms_m3"]``'s
    extras) shared in proportion to the zone's area of each part, and widened by the whole
    run's unclassified change (``unclassified_m3``: where it lies is not kept, so each zone
    may hold all of it)."""
    own = model(change_mask=region & zone, extra_sigma=None)
    extra = TERMS.index("extras")
    out = {}
    for part in ("net", "cut", "fill"):
        whole = headline["part_area_m2"][part]
        share = own["part_area_m2"][part] / whole if whole > 0 else 0.0
        terms = list(own["terms_m3"][part])
        terms[extra] = share * headline["terms_m3"][part][extra]
        out[part] = z_value(headline["confidence"]) * float(np.linalg.norm(terms))
    return widen(out, headline.get("unclassified_m3"))
