"""Piles found in a survey without polygons: regions rising above the surrounding ground.

The ground is the survey's morphological opening with a square as wide as the widest pile (a
pile narrower than the square is taken off; a plane, level or sloping, is kept as it is). Cells
standing above it by more than ten times the noise make candidate regions; a region is a pile
when its top stands at least ``min_height_m`` above the ground and it covers ``min_area_m2``.
Its outline, widened by two cells so that its toe runs on the ground, is the pile's polygon.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy
import shapely
from shapely.geometry.base import BaseGeometry

from .survey import Survey
from .types import Pile

EDGE_SIGMAS = 10.0  # cells this many noises above the ground belong to a region (its edge)
TOP_SIGMAS = 25.0  # a pile's top stands at least this many noises above the ground
LEAST_HEIGHT = 0.2  # m: and at least this high
LEAST_CELLS = 25  # a pile covers at least this many cells
MARGIN_CELLS = 2.0  # a found outline is widened by this many cells (its toe runs on the ground)


@dataclass(frozen=True)
class FindSettings:
    """How piles are found: ``widest_m`` the side of the opening's square (wider than the widest
    pile is across its narrowest), ``min_height_m`` and ``min_area_m2`` (None: from the noise and
    the cell size)."""

    widest_m: float = 40.0
    min_height_m: float | None = None
    min_area_m2: float | None = None


def find_piles(survey: Survey, settings: FindSettings | None = None) -> list[Pile]:
    """The piles standing above the ground of ``survey``, named ``pile 1`` ... from north-west."""
    settings = settings or FindSettings()
    cell = survey.grid.cell
    above = survey.filled - ground_of(survey, settings.widest_m)
    noise = survey.noise()
    top = settings.min_height_m if settings.min_height_m is not None else max(LEAST_HEIGHT, TOP_SIGMAS * noise)
    least = settings.min_area_m2 if settings.min_area_m2 is not None else LEAST_CELLS * cell * cell
    labels, count = scipy.ndimage.label(above > EDGE_SIGMAS * noise, structure=np.ones((3, 3)))
    if count == 0:
        return []
    index = np.arange(1, count + 1)
    highest = scipy.ndimage.maximum(above, labels, index)
    cells = scipy.ndimage.sum_labels(np.ones_like(above), labels, index)
    keep = index[(np.asarray(highest) >= top) & (np.asarray(cells) * cell * cell >= least)]
    polygons = [outline(labels == k, survey) for k in keep]
    polygons.sort(key=lambda p: (-round(p.centroid.y / (4 * cell)), p.centroid.x))
    return [Pile(p, f"pile {i + 1}") for i, p in enumerate(polygons)]


def ground_of(survey: Survey, widest_m: float) -> np.ndarray:
    """The survey's grey opening with a square of side ``widest_m`` (at least 3 cells, odd). The
    survey is extended beyond its edges by the higher of its point reflection (a slope rising to
    the edge goes on rising: a flat extension would make the opening cut into it) and its edge
    heights (a pile near the edge, reflected, is a pit that would lower the ground around it)."""
    k = max(3, int(round(widest_m / survey.grid.cell)) | 1)
    pad = k // 2 + 1
    h = survey.filled
    wide = np.maximum(np.pad(h, pad, mode="reflect", reflect_type="odd"), np.pad(h, pad, mode="edge"))
    return scipy.ndimage.grey_opening(wide, size=(k, k))[pad:-pad, pad:-pad]


def outline(mask: np.ndarray, survey: Survey) -> BaseGeometry:
    """The polygon (local) around the cells of ``mask``, widened by :data:`MARGIN_CELLS` cells,
    without holes, its steps smoothed by a quarter of a cell."""
    g = survey.grid
    rows, cols = np.nonzero(mask)
    x0, y0 = g.xmin - g.origin[0], g.ymax - g.origin[1]
    boxes = shapely.box(x0 + cols * g.cell, y0 - (rows + 1) * g.cell, x0 + (cols + 1) * g.cell, y0 - rows * g.cell)
    region = shapely.coverage_union_all(boxes).buffer(MARGIN_CELLS * g.cell, quad_segs=4)
    parts = sorted(shapely.get_parts(region), key=lambda p: p.area)
    return shapely.Polygon(parts[-1].exterior).simplify(g.cell / 4)
