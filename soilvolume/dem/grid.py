"""Average-height grids (DEMs) of both clouds on one shared grid: per cell the paper's mean, the
median or (default) a robust mean, which keeps stray outliers from becoming a cell's height."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import native
from ..core.polygons import covers
from ..core.types import GridSpec, SoilVolumeError
from ..native import axes
from ..soil.points import OBJECT, OTHER, VEGETATION
from .cellstats import BLOCK, OffsetSums, cell_heights
from .slopes import slopes


@dataclass(frozen=True)
class EpochDEM:
    """One epoch's average-height grid on the shared grid, each (rows, cols): heights (m, local
    frame, NaN where empty), point counts and robust height spreads (m) per cell."""

    heights: np.ndarray
    counts: np.ndarray
    spread: np.ndarray
    dx: np.ndarray | None = None  # mean offset (m) of the cell's points from its centre, east
    dy: np.ndarray | None = None  # the same, north
    veg: np.ndarray | None = None  # points per cell that are not soil: vegetation,
    obj: np.ndarray | None = None  # objects (buildings, wires),
    other: np.ndarray | None = None  # other (noise, water, unclassified)
    nonsoil_z: np.ndarray | None = None  # the sum of their heights (m, local)
    skew: np.ndarray | None = None  # the cell's height minus its points' median (m): what the statistic moved
    rule: Any = None  # soil.points.PointRule that labelled the points (None: none active)

    def nonsoil(self) -> np.ndarray:
        """Points per cell that are not soil (all kinds; 0 without a rule)."""
        parts = [a for a in (self.veg, self.obj, self.other) if a is not None]
        return sum(parts) if parts else np.zeros(self.counts.shape, np.int64)

    def all_points(self) -> np.ndarray:
        """Points per cell of every kind, soil or not."""
        return self.counts + self.nonsoil()

    def all_points_height(self) -> np.ndarray:
        """Each cell's mean height of every point, non-soil ones too (NaN where it has none)."""
        if self.nonsoil_z is None:
            return self.heights
        m = self.nonsoil()
        soil = np.where(self.counts > 0, np.nan_to_num(self.heights) * self.counts, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.counts + m > 0, (soil + self.nonsoil_z) / (self.counts + m), np.nan)

    def centred(self, cell: float, skip: np.ndarray | None = None) -> np.ndarray:
        """Heights moved from where each cell's points lie to its centre along the neighbours' slope (a
        cell covered on one side only, at a hole or an edge, otherwise holds that side's height);
        ``skip``: cells too weak to give a slope, left as they are."""
        if self.dx is None or self.dy is None:
            return self.heights
        base = self.heights if skip is None else np.where(skip, np.nan, self.heights)
        h = base
        for _ in range(CENTRING_PASSES):
            gx, gy = slopes(h, cell)
            h = base - np.nan_to_num(gx) * self.dx - np.nan_to_num(gy) * self.dy
        return h if skip is None else np.where(skip, self.heights, h)


CENTRING_PASSES = 4  # fixed-point passes: a moved cell gives its neighbours better slopes
EPOCH_ARRAYS = ("h", "n", "s", "x", "y", "v", "o", "q", "z", "m")  # an EpochDEM's arrays, in field order
ZERO_WHERE_EMPTY = set("nxyvoqzm")  # arrays that are 0 (not NaN) where a cell has no point
MOSTLY = 0.5  # a cell whose points are at least this share not soil has no soil height (colour rule)


def choose_cell(points: int, area_m2: float, per_cell: float = 8.0, minimum: float = 0.5) -> float:
    """Cell size (m) for ~``per_cell`` points per cell, at least ``minimum``, rounded up to 5 cm."""
    if points <= 0 or area_m2 <= 0:
        raise SoilVolumeError("cannot choose a cell size: no points in the compared area")
    cell = math.sqrt(per_cell * area_m2 / points)
    return max(minimum, math.ceil(cell * 20 - 1e-9) / 20)


def make_grid(
    lo: np.ndarray,
    hi: np.ndarray,
    cell: float,
    origin: np.ndarray,
    crs_wkt: str | None,
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
        raise SoilVolumeError(f"grid of {rows} x {cols} cells is too large: use a larger {{opt:cell}}")
    return GridSpec(xmin, ymax, cell, rows, cols, tuple(float(v) for v in origin), crs_wkt, xy_unit)


def cell_coords(xyz: np.ndarray, grid: GridSpec, window: tuple | None = None) -> tuple[np.ndarray, ...]:
    """Fractional column and row of every point (in its own precision) and the mask of those in the
    grid, or in its ``window`` of cells (r0, r1, c0, c1)."""
    inv = 1.0 / grid.cell
    col = (xyz[:, 0] - (grid.xmin - grid.origin[0])) * inv
    row = ((grid.ymax - grid.origin[1]) - xyz[:, 1]) * inv
    r0, r1, c0, c1 = window if window is not None else (0, grid.rows, 0, grid.cols)
    ok = (col >= c0) & (col < c1) & (row >= r0) & (row < r1)  # a cell's coordinates truncate to it
    return col, row, ok


def flat_ids(col: np.ndarray, row: np.ndarray, n_cols: int) -> np.ndarray:
    """Flat int64 cell ids of coordinates inside a grid, through int32 (at most 4e8 cells): the CPU
    converts floats to int32 in vectors, to int64 one by one."""
    ids = row.astype(np.int32).astype(np.int64)
    ids *= n_cols
    ids += col.astype(np.int32)
    return ids


def cell_ids(xyz: np.ndarray, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell id of every point inside the grid, and the mask of those points."""
    col, row, ok = cell_coords(xyz, grid)
    return flat_ids(col[ok], row[ok], grid.cols), ok


def average_height(xyz: np.ndarray, grid: GridSpec, statistic: str = "robust-mean") -> tuple[np.ndarray, ...]:
    """Per-cell height (NaN where empty) and count of the points ``xyz`` on ``grid`` (:func:`cell_heights`)."""
    ids, ok = cell_ids(xyz, grid)
    z = np.asarray(np.compress(ok, xyz[:, 2]), dtype=np.float64)
    return cell_heights(ids, z, (grid.rows, grid.cols), statistic)


def epoch_dem(xyz: np.ndarray, grid: GridSpec, statistic: str = "robust-mean", nonsoil=None, move=None) -> EpochDEM:
    """An :class:`EpochDEM` of one epoch's soil points (spreads, offsets from the cell centres) and
    its ``nonsoil`` points' counts (:func:`finish_epoch`). ``move``: applied to each block of
    :data:`BLOCK` points (no moved copy of the cloud); only cell ids and heights are kept whole."""
    sums = OffsetSums(grid.rows * grid.cols)
    ids, z = _cells_of(xyz, grid, move, sums)
    heights = cell_heights(ids, z, (grid.rows, grid.cols), statistic, full=True, own=True)
    del ids, z
    others, rule = None, None
    if nonsoil is not None:
        o_ids, o_ok = cell_ids(nonsoil.xyz, grid)
        others = nonsoil_sums(o_ids, nonsoil.labels[o_ok], nonsoil.xyz[o_ok, 2], (grid.rows, grid.cols))
        rule = nonsoil.rule
    return finish_epoch(heights, sums.means(heights[1], grid.cell), others, rule)


def _cells_of(xyz: np.ndarray, grid: GridSpec, move, sums: OffsetSums) -> tuple[np.ndarray, np.ndarray]:
    """(flat cell ids, float64 heights) of the points in ``grid``, in order, block by block (moved
    by ``move``); their centre offsets added to ``sums``."""
    ids, z = np.empty(len(xyz), np.int64), np.empty(len(xyz), np.float64)  # pages never written stay free
    m, lib = 0, native.kernels()
    for i in range(0, len(xyz), BLOCK):
        part = xyz[i : i + BLOCK] if move is None else move(xyz[i : i + BLOCK])
        if lib is not None and part.dtype == np.float32 and len(part):
            m += native_cells(lib, part, grid, (0, grid.rows, 0, grid.cols), ids[m:], z[m:], sums.sx, sums.sy)
            continue
        col, row, ok = cell_coords(part, grid)
        col, row = col[ok], row[ok]
        k = len(col)
        ids[m : m + k] = flat_ids(col, row, grid.cols)
        sums.add_at(ids[m : m + k], col, row)
        z[m : m + k] = np.compress(ok, part[:, 2])
        m += k
    return ids[:m], z[:m]


def native_cells(
    lib, part: np.ndarray, grid: GridSpec, win: tuple, ids: np.ndarray, z: np.ndarray, sx: np.ndarray, sy: np.ndarray
) -> int:
    """``sv_cells``: the float32 points of ``part`` in the window ``win`` (r0, r1, c0, c1) of ``grid``:
    flat ids and heights into ``ids`` and ``z``, offsets added to ``sx``/``sy`` (as
    :meth:`OffsetSums.add_at`), the bits of :func:`cell_coords`; returns how many."""
    part, addresses, step = axes(part, np.float32)  # (N, 3) rows or a (3, N) transposed as they are
    corner = (float(grid.xmin - grid.origin[0]), float(grid.ymax - grid.origin[1]), 1.0 / grid.cell)
    outs = (a.ctypes.data for a in (ids, z, sx, sy))
    return lib.sv_cells(*addresses, len(part), step, *corner, *(int(v) for v in win), *outs)


def nonsoil_sums(ids: np.ndarray, labels: np.ndarray, z: np.ndarray, shape: tuple[int, int]) -> tuple:
    """(vegetation, objects, other counts, sum of heights) per cell of non-soil points ``ids``."""
    n = shape[0] * shape[1]
    counts = tuple(np.bincount(ids[labels == k], minlength=n).reshape(shape) for k in (VEGETATION, OBJECT, OTHER))
    return (*counts, np.bincount(ids, weights=np.asarray(z, np.float64), minlength=n).reshape(shape))


def finish_epoch(heights: tuple, offsets: tuple, others: tuple | None, rule) -> EpochDEM:
    """An :class:`EpochDEM` from soil heights (h, n, s, skew), offsets and non-soil sums (None without
    a rule); with a colour rule a cell mostly not soil has no height (its "soil" points are canopy
    seen at a slant or mixed pixels)."""
    h, n, s, skew = heights
    if others is None:
        return EpochDEM(h, n, s, *offsets, skew=skew, rule=rule)
    if rule is not None and rule.empties_cells:
        m = others[0] + others[1] + others[2]
        gone = (m > 0) & (m >= MOSTLY * (m + n))
        h, s, skew = (np.where(gone, np.nan, a) for a in (h, s, skew))
        n = np.where(gone, 0, n)
    return EpochDEM(h, n, s, *offsets, *others, skew, rule)


def cell_for(xyz: np.ndarray, polygon: np.ndarray, minimum: float = 0.5) -> float:
    """:func:`choose_cell` from the density of ``xyz`` in ``polygon``, on about a million cells."""
    lo, hi = polygon.min(axis=0), polygon.max(axis=0)
    res = max(1.0, float(np.sqrt(np.prod(hi - lo) / 1e6)))
    lattice = make_grid(np.r_[lo, 0], np.r_[hi, 0], res, np.zeros(3), None)
    ids, _ = cell_ids(xyz, lattice)
    counts = np.bincount(ids, minlength=lattice.rows * lattice.cols)
    x, y = lattice.centers_local()
    ins = covers([polygon], x.ravel(), y.ravel())
    return choose_cell(int(counts[ins].sum()), float(ins.sum()) * res * res, minimum=minimum)


MASK_LAYER = "filled_mask"  # uint8 layers of a run, without units: the refilled cells,
CLASS_LAYER = "classes"  # and what is not soil (volumes/nonsoil.CLASS_CODES; resources/styles/excluded.qml)
UINT8_LAYERS = (MASK_LAYER, CLASS_LAYER)


def output_layers(correction: str) -> list[tuple[str, str, str]]:
    """An estimate's rasters: (file, the volume step's array, description); ``dem_`` ones local."""
    return [
        ("dem_before.tif", "dem_out_b", "average height, before; refilled where filled_mask is 1 (m)"),
        ("dem_after.tif", "dem_out_a", "average height, after; refilled where filled_mask is 1 (m)"),
        ("difference.tif", "diff", f"H_after - H_before - correction ({correction}) (m)"),
        ("plane_offset.tif", "offset", f"vertical correction d_i subtracted ({correction}) (m)"),
        ("filled_mask.tif", MASK_LAYER, "1 = difference interpolated (sparse cell or filled hole)"),
        ("excluded.tif", CLASS_LAYER, CLASS_LEGEND),
    ]


CLASS_LEGEND = (
    "what is not soil: 0 soil, 1 vegetation, 2 objects by classification, 3 other (noise, water, unclassified), "
    "4 moved object (left out), 5 object in one survey (counted), 6 rough change (counted)"
)
