"""report.html's map of a stockpile inventory: the survey's hillshade with each pile's polygon
outlined and numbered as in the table, a PNG drawn in numpy (:mod:`soilvolume.reporting`)."""

from __future__ import annotations

import numpy as np
import scipy
import shapely

from ..reporting.figures import hillshade
from ..reporting.svgparts import png_bytes
from .survey import Survey
from .types import Inventory

WIDTH = 720  # px: the map's width at least (small grids are enlarged cell by cell)
LARGEST = 2000  # px: larger grids are drawn every n-th cell
OUTLINE = np.array([214, 39, 40, 255], np.uint8)  # the piles' outlines
EMPTY = np.array([255, 255, 255, 255], np.uint8)  # cells without a height


def pile_labels(survey: Survey, inventory: Inventory) -> np.ndarray:
    """Per cell the number (1, 2, ...) of the pile whose polygon holds its centre; 0 elsewhere."""
    x, y = survey.centres()
    labels = np.zeros(x.shape, np.int32)
    for k, pile in enumerate(inventory.piles, 1):
        inside = shapely.contains_xy(pile.polygon, x, y)
        labels[inside & (labels == 0)] = k
    return labels


def map_png(survey: Survey, inventory: Inventory) -> bytes:
    """The map as PNG bytes: grey hillshade, white where the survey has no height, each pile's
    outline in red."""
    shade = hillshade(survey.filled, survey.grid.cell)
    grey = (60 + 180 * shade).astype(np.uint8)
    rgba = np.dstack([grey, grey, grey, np.full(grey.shape, 255, np.uint8)])
    rgba[~np.isfinite(survey.heights)] = EMPTY
    labels = pile_labels(survey, inventory)
    edge = (labels > 0) & (scipy.ndimage.minimum_filter(labels, size=3) != scipy.ndimage.maximum_filter(labels, size=3))
    rgba[edge] = OUTLINE
    step = int(np.ceil(max(rgba.shape[:2]) / LARGEST))
    rgba = rgba[::step, ::step]
    factor = max(1, int(np.ceil(WIDTH / rgba.shape[1])))
    return png_bytes(np.repeat(np.repeat(rgba, factor, axis=0), factor, axis=1))
