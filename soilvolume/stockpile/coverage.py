"""The polygon as the mask: the share of each grid cell a polygon covers (exact areas of the
cells its boundary crosses, 1 inside, 0 outside), over the window of cells around it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from ..core.types import GridSpec


@dataclass(frozen=True)
class Window:
    """Rows ``r0:r1`` and columns ``c0:c1`` of a grid around a polygon, with each cell's covered
    share ``share`` (r1 - r0, c1 - c0) and its cells' centres ``x``, ``y`` (local)."""

    r0: int
    r1: int
    c0: int
    c1: int
    share: np.ndarray
    x: np.ndarray
    y: np.ndarray

    @property
    def rows(self) -> slice:
        return slice(self.r0, self.r1)

    @property
    def cols(self) -> slice:
        return slice(self.c0, self.c1)

    def of(self, array: np.ndarray) -> np.ndarray:
        """``array`` (the whole grid's) cut to this window."""
        return array[self.rows, self.cols]


def window_of(polygon: BaseGeometry, grid: GridSpec, pad: int = 0) -> Window | None:
    """The :class:`Window` of the cells ``polygon`` (local) touches, widened by ``pad`` cells and
    clipped to the grid; None when the polygon lies outside the grid."""
    xmin, ymin, xmax, ymax = polygon.bounds
    x0, y0 = grid.xmin - grid.origin[0], grid.ymax - grid.origin[1]
    c0 = max(0, int(np.floor((xmin - x0) / grid.cell)) - pad)
    c1 = min(grid.cols, int(np.ceil((xmax - x0) / grid.cell)) + pad)
    r0 = max(0, int(np.floor((y0 - ymax) / grid.cell)) - pad)
    r1 = min(grid.rows, int(np.ceil((y0 - ymin) / grid.cell)) + pad)
    if c0 >= c1 or r0 >= r1:
        return None
    xs = x0 + (np.arange(c0, c1) + 0.5) * grid.cell
    ys = y0 - (np.arange(r0, r1) + 0.5) * grid.cell
    x, y = np.meshgrid(xs, ys)
    return Window(r0, r1, c0, c1, covered_share(polygon, x, y, grid.cell), x, y)


def covered_share(polygon: BaseGeometry, x: np.ndarray, y: np.ndarray, cell: float) -> np.ndarray:
    """The share (0..1) of each square cell of side ``cell`` centred on ``x``, ``y`` that
    ``polygon`` covers: cells wholly inside are 1 without any geometry built; the cells the
    boundary crosses get the exact area of their intersection."""
    h = cell / 2
    shapely.prepare(polygon)
    inside = shapely.contains_xy(polygon, x, y)
    near = shapely.dwithin(polygon.boundary, shapely.points(x, y), h * np.sqrt(2) * 1.0001)
    share = inside.astype(np.float64)
    if near.any():
        xb, yb = x[near], y[near]
        boxes = shapely.box(xb - h, yb - h, xb + h, yb + h)
        share[near] = np.clip(shapely.area(shapely.intersection(boxes, polygon)) / (cell * cell), 0.0, 1.0)
    return share
