"""One survey as a height grid for the stockpile inventory: from points (the engine's cell
statistic, :func:`soilvolume.dem.grid.average_height`) or from a DEM already on a grid."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..core.types import GridSpec
from ..dem.grid import average_height, cell_ids, choose_cell, make_grid
from .types import PileError

NOISE_FLOOR = 0.002  # m: the least noise per cell assumed (a synthetic surface without any)


@dataclass(frozen=True)
class CellErrors:
    """Each cell height's ``sigma`` (standard error, m; NaN where unknown) and ``offset`` (the plain
    mean of its points less its height, m; 0 where unknown): what the cell statistic moved it by."""

    sigma: np.ndarray
    offset: np.ndarray


@dataclass(frozen=True)
class Survey:
    """A survey on a grid: ``heights`` (local m, NaN where empty), ``counts`` (points per cell, 1
    per known cell for a DEM), ``errors`` (:class:`CellErrors`: :func:`standard_errors`), ``filled``
    (heights with empty cells filled from their nearest known cell, for morphology and toe fits)."""

    grid: GridSpec
    heights: np.ndarray
    counts: np.ndarray
    errors: CellErrors
    filled: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """Each cell height's standard error (m; NaN where unknown)."""
        return self.errors.sigma

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre x and y (local), each (rows, cols)."""
        return self.grid.centers_local()

    def noise(self) -> float:
        """A robust estimate of the heights' noise per cell (m): the spread of each height about
        its 3 x 3 neighbours' mean, where all nine are known (slopes cancel in the mean)."""
        known = np.isfinite(self.heights)
        local = scipy.ndimage.uniform_filter(self.filled, size=3, mode="nearest")
        full = scipy.ndimage.minimum_filter(known.astype(np.uint8), size=3, mode="constant") > 0
        resid = (self.filled - local)[full]
        if resid.size < 9:
            return NOISE_FLOOR
        mad = float(np.median(np.abs(resid - np.median(resid))))
        return max(NOISE_FLOOR, 1.4826 * mad / np.sqrt(8.0 / 9.0))


def survey_from_points(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    cell: float | None = None,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    crs_wkt: str | None = None,
) -> Survey:
    """The :class:`Survey` of points ``x, y, z`` (local m); ``cell`` (m) by default from their
    density (:func:`soilvolume.dem.grid.choose_cell`: about 8 points per cell, at least 0.5 m)."""
    xyz = np.column_stack([x, y, z]).astype(np.float64)
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    if len(xyz) < 3:
        raise PileError("the survey has fewer than 3 points with finite coordinates")
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    if cell is None:
        cell = choose_cell(len(xyz), float(np.prod(np.maximum(hi[:2] - lo[:2], 1e-6))))
    grid = make_grid(lo, hi, float(cell), np.asarray(origin, dtype=np.float64), crs_wkt)
    h, n = average_height(xyz, grid)
    return Survey(grid, h, n, standard_errors(xyz, grid, h, n), fill_nearest(h))


def standard_errors(xyz: np.ndarray, grid: GridSpec, h: np.ndarray, n: np.ndarray) -> CellErrors:
    """The :class:`CellErrors` of heights ``h``: each one's standard error (the root mean square of
    its points' heights about it over the root of their count less one; NaN with fewer than 2
    points; not the robust spread: the interquartile range of a few points underestimates their
    spread) and the mean of those departures (the offset; 0 for the plain mean)."""
    ids, ok = cell_ids(xyz, grid)
    resid = xyz[ok, 2] - h.ravel()[ids]
    total = np.bincount(ids, weights=resid, minlength=h.size).reshape(h.shape)
    sq = np.bincount(ids, weights=resid * resid, minlength=h.size).reshape(h.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.where(n > 1, np.sqrt(sq / np.maximum(n - 1, 1) / np.maximum(n, 1)), np.nan)
        offset = np.where((n > 0) & np.isfinite(h), total / np.maximum(n, 1), 0.0)
    return CellErrors(sigma, offset)


def survey_from_dem(heights: np.ndarray, grid: GridSpec, noise_m: float | None = None) -> Survey:
    """The :class:`Survey` of a DEM ``heights`` (local m, NaN where empty) on ``grid``;
    ``noise_m``: each height's standard error if known (else estimated from the DEM itself)."""
    h = np.asarray(heights, dtype=np.float64)
    if h.shape != (grid.rows, grid.cols):
        raise PileError(f"the DEM is {h.shape[0]} x {h.shape[1]} cells, its grid {grid.rows} x {grid.cols}")
    if not np.isfinite(h).any():
        raise PileError("the DEM has no height")
    n = np.isfinite(h).astype(np.int64)
    sigma = np.full(h.shape, np.nan if noise_m is None else float(noise_m))
    return Survey(grid, h, n, CellErrors(sigma, np.zeros(h.shape)), fill_nearest(h))


def fill_nearest(h: np.ndarray) -> np.ndarray:
    """``h`` with every NaN replaced by its nearest known cell's value."""
    empty = ~np.isfinite(h)
    if not empty.any():
        return h.copy()
    idx = scipy.ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
    return h[tuple(idx)]


def fill_linear(h: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """``h`` (a window of heights) with its empty cells interpolated linearly between the known
    ones around them (a hole in a pile's face follows the face); those outside the known cells'
    hull take ``nearest`` (:attr:`Survey.filled`'s)."""
    empty = ~np.isfinite(h)
    if not empty.any() or empty.all():
        return np.where(empty, nearest, h)
    rows, cols = np.nonzero(~empty)
    er, ec = np.nonzero(empty)
    try:
        z = scipy.interpolate.griddata((rows, cols), h[rows, cols], (er, ec), method="linear")
    except Exception:  # noqa: BLE001 - Qhull refuses known cells all in a line
        z = np.full(er.shape, np.nan)
    out = h.copy()
    out[er, ec] = np.where(np.isfinite(z), z, nearest[er, ec])
    return out
