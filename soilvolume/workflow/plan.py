"""The one grid planner and default-cell rule of every product and backend: ``--cell``, else about eight
reference points per cell over the footprint compared (:func:`soilvolume.dem.grid.choose_cell`), counted by
a tiled run from its columns so both backends pick the same cell; the grid over the epochs' boxes' overlap."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..core.cells import bounds
from ..core.polygons import covers
from ..core.types import GridSpec, SoilVolumeError
from ..core.wording import opt
from ..dem.grid import cell_for, choose_cell, make_grid
from ..inputs.crs import WorkFrame
from ..inputs.footprint import footprint, polygon_area
from ..inputs.prepare import Prepared
from ..options import Options
from ..validate import OptionError

#: fewest grid cells over the compared area that give a meaningful volume
MIN_CELLS = 25


def given_cell(options: Options) -> float | None:
    """``--cell`` when given (a positive size), else None: the default rule decides."""
    return options.cell if options.cell is not None and options.cell > 0 else None


def reference_cell(prep: Prepared, poly: np.ndarray, options: Options) -> float:
    """The cell of a pair: ``--cell``, else from the before points within ``poly`` (the registered
    after footprint), or in a tiled run the counts behind the before columns centred inside it."""
    cell = given_cell(options)
    if cell is not None:
        return cell
    if len(prep.before):
        return cell_for(prep.before.xyz, poly)
    ins = covers([poly], prep.before_thin[:, 0], prep.before_thin[:, 1])
    return choose_cell(int(prep.before_counts[ins].sum()), polygon_area(poly))


def survey_cell(xyz: np.ndarray, thin: np.ndarray, options: Options) -> float:
    """The cell of a survey compared with a surface: ``--cell``, else from its points over its footprint."""
    cell = given_cell(options)
    return cell if cell is not None else cell_for(xyz, footprint(thin[:, :2]))


def cloud_cell(xyz: np.ndarray, thin: np.ndarray, options: Options) -> float:
    """The cell of one cloud's DEM: ``--cell``, else from all its points over its footprint's area."""
    cell = given_cell(options)
    return cell if cell is not None else choose_cell(len(xyz), polygon_area(footprint(thin[:, :2])))


def plan_grid(cell: float, boxes: Sequence[tuple], origin: np.ndarray, frame: WorkFrame, empty: str) -> GridSpec:
    """The grid of ``cell`` over the overlap of ``boxes`` (local (lo, hi) pairs, x/y first, or the points'
    own); ``empty``: the error when they do not overlap."""
    boxes = [bounds(b, 2) if isinstance(b, np.ndarray) else b for b in boxes]  # the native one pass
    lo = np.max([np.asarray(b[0], float)[:2] for b in boxes], axis=0)
    hi = np.min([np.asarray(b[1], float)[:2] for b in boxes], axis=0)
    if (hi <= lo).any():
        raise SoilVolumeError(empty)
    grid = make_grid(lo, hi, cell, origin, frame.wkt, frame.xy_unit)
    if (n := grid.rows * grid.cols) < MIN_CELLS:  # a cell as large as the site makes noise
        raise OptionError(
            "cell",
            f"a {cell:g} m grid has only {n} cell(s) over the compared area "
            f"(at least {MIN_CELLS} needed); use a smaller {opt('cell')} or leave it unset "
            "to derive it from the point density",
        )
    return grid
