"""A pile volume's 95 % interval: the noise of its cells, the noise of the toe heights its base
is built from (carried through the base's own weights, neighbouring toe heights correlated as
their windows overlap), how far the bases that follow the toe move it and how far the cell
statistic moves it from the plain mean of the points."""

from __future__ import annotations

import numpy as np
import scipy

from .bases import extreme, level_heights, tin_at
from .coverage import Window
from .toe import Toe
from .types import FOLLOWING, TOE_BASES, Base

Z95 = 1.959964  # two-sided 95 % of a normal distribution


def half_width(base: Base, toe: Toe, window: Window, cell_area: float, sigma: np.ndarray, shifts: float) -> float:
    """The interval's half-width (m3): 95 % of the cells' and the toe's noise, plus ``shifts``
    (m3: :func:`base_spread` and :func:`statistic_shift`), for cell standard errors ``sigma``
    (the window's, m)."""
    area = window.share * cell_area
    sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, toe.noise)
    cells = float(np.sum((area * sigma) ** 2))
    return Z95 * np.sqrt(cells + toe_variance(base.kind, toe, window, cell_area)) + shifts


def statistic_shift(window: Window, cell_area: float, offset: np.ndarray) -> float:
    """How far the plain mean of each cell's points would move the volume (m3), for the window's
    cell ``offset`` (m, :class:`~.survey.CellErrors`). The plain mean's sum is the surface's
    integral; a robust statistic drops the points of a cell a break line crosses (a toe, a crest)
    as outliers, which no single cell tells from real ones: the interval holds both."""
    return abs(float(np.sum(window.share * cell_area * offset)))


def base_spread(volumes: dict[str, float], volume: float, base: Base, level: bool) -> float:
    """How far the bases that follow the toe (:data:`FOLLOWING`, and the average where the toe
    is ``level``) move the volume from ``volume`` (m3); 0 for a given elevation or surface."""
    if base.kind not in TOE_BASES:
        return 0.0
    kinds = FOLLOWING + (("average",) if level else ())
    return float(max(abs(volumes[k] - volume) for k in kinds))


def toe_variance(kind: str, toe: Toe, window: Window, cell_area: float) -> float:
    """The variance (m6) the toe heights' noise gives the volume over toe base ``kind`` (0 for
    a given base): the base's weights on the toe heights, with the heights of toe points closer
    than a window correlated by the share of cells their windows have in common."""
    if kind not in TOE_BASES:
        return 0.0
    some = window.share > 0
    a = base_weights(kind, toe, window.x[some], window.y[some], window.share[some] * cell_area) * toe.sigma
    xy = np.column_stack([toe.x, toe.y])
    pairs = scipy.spatial.cKDTree(xy).query_pairs(toe.reach * np.sqrt(2), output_type="ndarray")
    d = np.abs(xy[pairs[:, 0]] - xy[pairs[:, 1]]) / toe.reach
    rho = np.prod(np.clip(1 - d, 0, None), axis=1)
    total = np.sum(a * a) + 2 * np.sum(a[pairs[:, 0]] * a[pairs[:, 1]] * rho)
    return float(total)


def base_weights(kind: str, toe: Toe, x: np.ndarray, y: np.ndarray, area: np.ndarray) -> np.ndarray:
    """How much the base's integral over cells at ``x``, ``y`` of ``area`` (m2) moves per metre
    of each toe height (m2 per toe point): the base is linear in the toe heights."""
    if kind == "triangulated":
        tin = tin_at(toe, x, y)
        inside = tin.inside
        share = (tin.weights[inside] * area[inside, None]).ravel()
        w = np.bincount(tin.corners[inside].ravel(), weights=share, minlength=len(toe.z))
        return w + plane_weights(toe, x[~inside], y[~inside], area[~inside])
    if kind == "plane":
        return plane_weights(toe, x, y, area)
    if kind == "average":
        return area.sum() * toe.weight / toe.weight.sum()
    return level_weights(kind, toe, area.sum())


def level_weights(kind: str, toe: Toe, area: float) -> np.ndarray:
    """:func:`base_weights` of the ``lowest`` or ``highest`` level over ``area`` (m2): its toe
    point's plane height, plus its departure from the plane times the garrote's ``gain``."""
    k = extreme(kind, toe)
    gain = level_heights(toe)[1][k]
    w = (1 - gain) * plane_weights(toe, toe.x[k : k + 1], toe.y[k : k + 1], np.array([area]))
    w[k] += gain * area
    return w


def plane_weights(toe: Toe, x: np.ndarray, y: np.ndarray, area: np.ndarray) -> np.ndarray:
    """:func:`base_weights` of the toe's least-squares plane."""
    p = toe.weight / toe.weight.sum()
    design = np.column_stack([np.ones_like(toe.x), toe.x, toe.y])
    moments = (design * p[:, None]).T @ design
    g = np.array([area.sum(), np.sum(area * x), np.sum(area * y)])
    return p * (design @ np.linalg.solve(moments, g))
