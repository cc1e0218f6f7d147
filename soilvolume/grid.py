"""Average-height grids (DEMs) of both clouds on one shared grid, and GeoTIFF writing.

The per-cell statistic is the paper's mean, the median, or (default) a robust mean: the mean of
the points within 3 MAD (scaled, floor 1 cm) of the cell median, which keeps stray outliers and
floaters from becoming a whole cell's height.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .io import atomic_path
from .types import GridSpec, SoilVolumeError

NODATA = -9999.0


def choose_cell(points: int, area_m2: float, per_cell: float = 8.0, minimum: float = 0.5) -> float:
    """Cell size (m) giving about ``per_cell`` points per cell, at least ``minimum``, rounded up
    to 5 cm."""
    if points <= 0 or area_m2 <= 0:
        raise SoilVolumeError("cannot choose a cell size: no points in the compared area")
    cell = math.sqrt(per_cell * area_m2 / points)
    return max(minimum, math.ceil(cell * 20 - 1e-9) / 20)


def make_grid(
    lo: np.ndarray, hi: np.ndarray, cell: float, origin: np.ndarray, crs_wkt: str | None,
    xy_unit: float = 1.0,
) -> GridSpec:
    """A grid covering local bounds ``lo``..``hi`` with edges on absolute multiples of ``cell``."""
    xmin = math.floor((lo[0] + origin[0]) / cell) * cell
    ymin = math.floor((lo[1] + origin[1]) / cell) * cell
    xmax = math.ceil((hi[0] + origin[0]) / cell) * cell
    ymax = math.ceil((hi[1] + origin[1]) / cell) * cell
    cols = max(1, round((xmax - xmin) / cell))
    rows = max(1, round((ymax - ymin) / cell))
    if rows * cols > 400_000_000:
        raise SoilVolumeError(f"grid of {rows} x {cols} cells is too large: use a larger --cell")
    return GridSpec(xmin, ymax, cell, rows, cols, tuple(float(v) for v in origin), crs_wkt, xy_unit)


def cell_ids(xyz: np.ndarray, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell id of every point inside the grid, and the mask of those points."""
    row, col, ok = grid.index(xyz[:, :2])
    return row[ok] * grid.cols + col[ok], ok


def average_height(
    xyz: np.ndarray, grid: GridSpec, statistic: str = "robust-mean", k_mad: float = 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell height (NaN where empty) and point count, both (rows, cols)."""
    ids, ok = cell_ids(xyz, grid)
    z = xyz[ok, 2]
    n = grid.rows * grid.cols
    counts = np.bincount(ids, minlength=n)
    if statistic == "mean":
        heights = _mean(ids, z, counts, n)
    elif statistic in ("median", "robust-mean"):
        order = np.lexsort((z, ids))
        ids_s, z_s = ids[order], z[order]
        med = _sorted_median(z_s, counts)
        if statistic == "median":
            heights = med
        else:
            dev = np.abs(z_s - med[ids_s])
            order2 = np.lexsort((dev, ids_s))
            mad = _sorted_median(dev[order2], counts) * 1.4826
            keep = dev <= k_mad * np.maximum(mad[ids_s], 0.01)
            kept = np.bincount(ids_s[keep], minlength=n)
            heights = _mean(ids_s[keep], z_s[keep], kept, n)
    else:
        raise SoilVolumeError(f"unknown cell statistic '{statistic}'")
    return heights.reshape(grid.rows, grid.cols), counts.reshape(grid.rows, grid.cols)


def _mean(ids: np.ndarray, z: np.ndarray, counts: np.ndarray, n: int) -> np.ndarray:
    sums = np.bincount(ids, weights=z, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def _sorted_median(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Median per cell of values already sorted by (cell, value); NaN for empty cells."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    has = counts > 0
    lo = starts + (counts - 1) // 2
    hi = starts + counts // 2
    out = np.full(counts.shape, np.nan)
    out[has] = 0.5 * (values[lo[has]] + values[hi[has]])
    return out


def write_geotiff(
    path: str | Path, array: np.ndarray, grid: GridSpec, description: str = "",
    units: str = "metre", dtype: str = "float32",
) -> Path:
    """Write a single-band GeoTIFF (NaN -> nodata), atomically; returns the path."""
    import rasterio

    path = Path(path)
    nodata = NODATA if np.dtype(dtype).kind == "f" else 255
    data = np.where(np.isfinite(array), array, nodata).astype(dtype)
    profile = dict(
        driver="GTiff", width=grid.cols, height=grid.rows, count=1, dtype=dtype,
        crs=grid.crs_wkt, transform=grid.transform, nodata=nodata, compress="deflate",
        tiled=grid.cols >= 256 and grid.rows >= 256,
    )
    with atomic_path(path) as tmp:
        with rasterio.open(tmp, "w", **profile) as dst:
            dst.write(data, 1)
            dst.set_band_description(1, description)
            dst.set_band_unit(1, units)
            dst.update_tags(AREA_OR_POINT="Area")
    return path
