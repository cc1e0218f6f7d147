"""The raster statistics of PDAL's writers.gdal (GDALGrid), vectorised.

The grid's lower-left corner is (origin_x, origin_y); cell (i, j) spans
[x0 + i*res, x0 + (i+1)*res) x [y0 + j*res, y0 + (j+1)*res), j counted from the bottom. With
``binmode`` a point feeds only the cell it falls in; otherwise every cell whose centre is strictly
closer than ``radius``. Empty cells are NaN (count 0) unless ``window_size`` fills them by inverse
(Chebyshev cell) distance weighting of non-empty cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.cells import cell_index

STATS = ("min", "max", "mean", "idw", "count", "stdev")


@dataclass(frozen=True)
class Grid:
    x0: float
    y0: float
    width: int
    height: int
    res: float


def grid_from_bounds(minx: float, miny: float, maxx: float, maxy: float, res: float) -> Grid:
    """PDAL's createGrid: width = floor((maxx - minx) / res) + 1, same for height."""
    return Grid(minx, miny, int(math.floor((maxx - minx) / res)) + 1, int(math.floor((maxy - miny) / res)) + 1, res)


def _accumulate(grid: Grid, i, j, v, d, stats: set[str], power: float) -> dict[str, np.ndarray]:
    size = grid.width * grid.height
    ok = (i >= 0) & (j >= 0) & (i < grid.width) & (j < grid.height)
    flat = (j[ok] * grid.width + i[ok]).astype(np.int64)
    v, d = v[ok], d[ok]
    out: dict[str, np.ndarray] = {}
    count = np.bincount(flat, minlength=size).astype(np.float64)
    out["count"] = count
    if "min" in stats:
        out["min"] = np.full(size, np.inf)
        np.minimum.at(out["min"], flat, v)
    if "max" in stats:
        out["max"] = np.full(size, -np.inf)
        np.maximum.at(out["max"], flat, v)
    if stats & {"mean", "stdev"}:
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.bincount(flat, weights=v, minlength=size) / count
        out["mean"] = mean
        if "stdev" in stats:
            dev = (v - mean[flat]) ** 2
            with np.errstate(invalid="ignore", divide="ignore"):
                out["stdev"] = np.sqrt(np.bincount(flat, weights=dev, minlength=size) / count)
    if "idw" in stats:
        exact = d == 0
        with np.errstate(divide="ignore"):
            w = np.where(exact, 0.0, 1.0 / np.power(np.where(exact, 1.0, d), power))
        num = np.bincount(flat, weights=v * w, minlength=size)
        den = np.bincount(flat, weights=w, minlength=size)
        with np.errstate(invalid="ignore", divide="ignore"):
            idw = num / den
        hit = np.full(size, -1, dtype=np.int64)  # value of the first point at distance 0
        first = np.flatnonzero(exact)[::-1]
        hit[flat[first]] = first
        idw[hit >= 0] = v[hit[hit >= 0]]
        out["idw"] = idw
    return out


def compute(
    grid: Grid, x, y, v, *, stats=STATS, binmode=False, radius=None, power=1.0, window_size=0
) -> dict[str, np.ndarray]:
    """Rasters (height x width, row 0 = top, i.e. GDAL order) of the requested statistics."""
    stats = set(stats)
    radius = grid.res * math.sqrt(2.0) if radius is None else radius
    ci, cj = cell_index(x, grid.x0, grid.res), cell_index(y, grid.y0, grid.res)
    if binmode:
        dist = np.hypot(grid.x0 + (ci + 0.5) * grid.res - x, grid.y0 + (cj + 0.5) * grid.res - y)
        acc = _accumulate(grid, ci, cj, v, dist, stats, power)
    else:
        reach = int(math.ceil(radius / grid.res)) + 1
        parts: list[tuple] = []
        for di in range(-reach, reach + 1):
            for dj in range(-reach, reach + 1):
                # nearest a point of the cell can be to that centre: skip unreachable offsets
                if math.hypot(max(0, abs(di) - 0.5), max(0, abs(dj) - 0.5)) * grid.res >= radius:
                    continue
                i, j = ci + di, cj + dj
                d = np.hypot(grid.x0 + (i + 0.5) * grid.res - x, grid.y0 + (j + 0.5) * grid.res - y)
                m = d < radius
                parts.append((i[m], j[m], v[m], d[m]))
        i, j, vv, dd = (np.concatenate(p) for p in zip(*parts, strict=True))
        acc = _accumulate(grid, i, j, vv, dd, stats, power)
    shape = (grid.height, grid.width)
    empty = acc["count"] == 0
    for name in stats - {"count"}:
        acc[name][empty] = np.nan
    out = {k: a.reshape(shape) for k, a in acc.items()}
    if window_size > 0:
        _window_fill(out, empty.reshape(shape), stats - {"count"}, window_size)
    return {k: np.flipud(out[k]) for k in STATS if k in stats}


def _window_fill(out: dict, empty: np.ndarray, names: set[str], w: int) -> None:
    """PDAL's fallback: empty cells get the inverse-distance mean of non-empty cells within a
    (2w+1)^2 window (distance = Chebyshev cell distance); filled cells are not donors."""
    h, wd = empty.shape
    dsum = np.zeros(empty.shape)
    sums = {n: np.zeros(empty.shape) for n in names}
    for di in range(-w, w + 1):
        for dj in range(-w, w + 1):
            if di == 0 and dj == 0:
                continue
            dist = float(max(abs(di), abs(dj)))
            src = (slice(max(0, dj), h + min(0, dj)), slice(max(0, di), wd + min(0, di)))
            dst = (slice(max(0, -dj), h + min(0, -dj)), slice(max(0, -di), wd + min(0, -di)))
            donor = ~empty[src]
            dsum[dst] += donor / dist
            for n in names:
                sums[n][dst] += np.where(donor, np.nan_to_num(out[n][src]), 0.0) / dist
    fill = empty & (dsum > 0)
    for n in names:
        out[n][fill] = sums[n][fill] / dsum[fill]
