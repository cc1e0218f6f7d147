"""Per-zone volume budgets and polygon masks of a vector file (read and reprojected by
:mod:`.polygons`, cell centres inside rasterised with rasterio). A zone with no cell on the grid is
flagged, never a silent 0 m3; when no zone meets the grid the run fails."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import GridSpec, SoilVolumeError
from .change import budget, signed_budget
from .polygons import Polygon, read_polygons, to_grid_crs
from .uncertainty import TERMS, widen, z_value

# The grid's transform is given, yet GDAL's scratch raster inside rasterize warns all the same. A
# filter for the process, not ``catch_warnings``: that swaps the global filter list and is not
# thread-safe (tile tasks run on threads; a neighbour's exit let the warning reach stderr).
warnings.filterwarnings("ignore", message="Dataset has no geotransform", module="rasterio.features")


def on_grid(path: str | Path, grid: GridSpec, name_field: str | None = None, what: str = "zones file"):
    """(the polygons of ``path`` in the grid's CRS, the file's CRS WKT)."""
    polys, wkt = read_polygons(path, name_field, what)
    return to_grid_crs(polys, wkt, grid, path), wkt


def polygon_masks(polys: list[Polygon], grid: GridSpec) -> list[np.ndarray]:
    """One boolean (rows, cols) mask per polygon (cells whose centre is inside)."""
    from rasterio import features

    shape = (grid.rows, grid.cols)
    return [
        features.rasterize([(p.geometry, 1)], out_shape=shape, transform=grid.transform, dtype="uint8").astype(bool)
        for p in polys
    ]


def polygons_mask(path: str | Path, grid: GridSpec, what: str = "{opt:stable_mask} file") -> np.ndarray:
    """Union of the polygons of ``path`` as a (rows, cols) mask; none meeting the grid is an error."""
    polys, wkt = on_grid(path, grid, what=what)
    u = grid.xy_unit  # the grid's extent in its CRS's units, met by a polygon's bounds
    gx0, gy1 = grid.xmin / u, grid.ymax / u
    gx1, gy0 = gx0 + grid.cols * grid.cell / u, gy1 - grid.rows * grid.cell / u
    if not any(
        x0 <= gx1 and gx0 <= x1 and y0 <= gy1 and gy0 <= y1 for x0, y0, x1, y1 in (p.geometry.bounds for p in polys)
    ):
        raise SoilVolumeError(f"{path}: no polygon of this {what} meets the survey's grid{_crs_hint(wkt)}")
    return np.logical_or.reduce(polygon_masks(polys, grid))


def _crs_hint(wkt: str | None) -> str:
    return " (the file has no CRS: is it in the survey's?)" if not wkt else " (is its CRS right?)"


def zone_budgets(
    diff: np.ndarray,
    grid: GridSpec,
    zones_path: str | Path,
    name_field: str | None = None,
    whole: bool = True,
    interval: Callable[[np.ndarray], dict[str, float]] | None = None,
    areas: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[dict[str, Any]]:
    """Per polygon: id, name, budget, zone and polygon areas; ``interval`` its ±; fill and cut over ``areas`` as the
    headline's."""
    polys, wkt = on_grid(zones_path, grid, name_field)
    out = []
    for p, mask in zip(polys, polygon_masks(polys, grid), strict=True):
        b = budget(diff, grid.cell_area, mask)  # the finite cells' net, cut, fill and compared area
        row = {"id": p.id, "name": p.name, **{k: b[k] for k in ("net", "cut", "fill", "area_m2")}}
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
    """The verdict's sentences on zones outside the grid, in part or whole, or repaired."""
    outside = [r["name"] for r in rows if r.get("outside_grid")]
    part = [r["name"] for r in rows if not r.get("outside_grid") and r["zone_area_m2"] < 0.9 * r["polygon_area_m2"]]
    fixed = [r["name"] for r in rows if r.get("repaired")]
    said = (
        "zones without a grid cell centre inside (outside the survey, in another CRS than declared, or smaller "
        "than a cell): their volumes are not measured: {}",
        "zones only partly on the surveyed grid (their volumes cover that part): {}",
        "zones whose invalid geometry (e.g. self-intersecting) was repaired: {}",
    )
    return [words.format(_names(names)) for words, names in zip(said, (outside, part, fixed), strict=True) if names]


def _names(names: list[str], limit: int = 5) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def zone_interval(model: Callable[..., dict], region: np.ndarray, headline: dict, zone: np.ndarray) -> dict[str, float]:
    """A zone's ± (m^3): ``model`` over ``region`` in ``zone``, a share of the extras, widened by all the
    unclassified."""
    own = model(change_mask=region & zone, extra_sigma=None)
    extra = TERMS.index("extras")
    out = {}
    for part in ("net", "cut", "fill"):
        whole = headline["part_area_m2"][part]
        terms = list(own["terms_m3"][part])
        terms[extra] = (own["part_area_m2"][part] / whole if whole > 0 else 0.0) * headline["terms_m3"][part][extra]
        out[part] = z_value(headline["confidence"]) * float(np.linalg.norm(terms))
    return widen(out, headline.get("unclassified_m3"))
