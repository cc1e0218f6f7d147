"""One tile of the shared grid as a Dask task: both epochs' points that can meet it, their heights,
counts and spreads by :func:`grid.cell_heights` on the *global* grid's cells, as in-process."""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace

import numpy as np
import pyproj

from .. import native
from ..core.cells import in_box
from ..core.types import GridSpec
from ..dem.grid import (
    EPOCH_ARRAYS,
    ZERO_WHERE_EMPTY,
    EpochDEM,
    OffsetSums,
    cell_coords,
    cell_heights,
    finish_epoch,
    native_cells,
    nonsoil_sums,
)
from ..inputs.crs import WorkFrame, z_unit
from ..inputs.footprint import PolygonMask
from ..inputs.io import GROUND
from ..inputs.prepare import _local
from ..inputs.stream import open_source
from ..registration.rigid import transform_points32
from .pointcache import chunks, kept_chunk
from .tilestore import Window

TILE_ARRAYS = tuple(f"{k}_{e}" for e in "ab" for k in EPOCH_ARRAYS)  # what a tile task returns: h_a, n_a, ...


def empty_value(name: str) -> float:
    """A tile array's value where no point fell: 0 (counts, centre offsets) or NaN."""
    return 0 if name[0] in ZERO_WHERE_EMPTY else np.nan


@dataclass(frozen=True)
class Plan:
    """Everything a tile task needs (picklable: sent to the workers)."""

    before: str
    after: str
    crs_b: str  # WKT of each file's CRS (header or override)
    crs_a: str
    frame: WorkFrame
    origin: np.ndarray
    grid: GridSpec
    transform: np.ndarray  # after -> before, local frame
    ground: tuple[bool, bool]  # (before, after): class 2 only
    crop: np.ndarray  # the before crop polygon (local), as in-process
    statistic: str
    index: tuple = (None, None)  # (before, after): chunk boxes of single files, for bounded reads
    rules: tuple = (None, None)  # (before, after): soil.points.PointRule of each epoch (None: class 2 by ground)
    # what the driver opened already, so no task reads them again (not part of the tiles' key):
    sources: tuple = (None, None)  # (before, after) stream.Source from the headers (a VPC's tiles)
    mask: PolygonMask | None = None  # the crop as a lattice


def crop_mask(plan: Plan) -> PolygonMask:
    """The before crop as a lattice: the plan's, or made from its polygon."""
    return plan.mask or PolygonMask(plan.crop)


def grid_tile(plan: Plan, win: Window, cached: tuple = (None, None)) -> tuple[dict[str, np.ndarray], dict]:
    """({name of :data:`TILE_ARRAYS`: array}, stats: points read, seconds) of one tile;
    ``cached``: (before, after) {path: KeptTile} of VPC tiles in memory (:mod:`.pointcache`)."""
    t0, stats = time.perf_counter(), {"read": 0, "cached": 0}
    before = _epoch(plan, 0, win, crop_mask(plan), stats, cached[0])
    after = _epoch(plan, 1, win, None, stats, cached[1])
    stats["seconds"] = time.perf_counter() - t0
    return dict(zip(TILE_ARRAYS, (*after, *before), strict=True)), stats


def window_source(plan: Plan, epoch: int, win: Window) -> tuple:
    """(CRS, source read only where it can meet the window, that x/y box or None) of epoch 0 or 1."""
    crs = pyproj.CRS.from_wkt((plan.crs_b, plan.crs_a)[epoch])
    src = plan.sources[epoch] or open_source((plan.before, plan.after)[epoch])
    src = replace(src, index=plan.index[epoch])
    box = _read_box(plan, crs, win, plan.transform if epoch else None)
    return crs, (src if box is None else src.within(*box)), box


def _epoch(plan: Plan, epoch: int, win: Window, keep, stats: dict, cached: dict | None = None):
    """Heights, counts, spreads and centre offsets of epoch 0 or 1 on the window's cells;
    ``cached``: {path: KeptTile} of the epoch's VPC tiles in memory."""
    transform = plan.transform if epoch else None
    shape = (win[1] - win[0], win[3] - win[2])
    ids, zs, offsets = [], [], OffsetSums(shape[0] * shape[1])
    rule, (src, made) = plan.rules[epoch], _file_chunks(plan, epoch, win, keep, stats)
    if rule is None and plan.ground[epoch]:
        cached = None  # kept tiles hold every class: class 2 is chosen from the files' classes
    o_ids, o_lab, o_z = [np.empty(0, np.int32)], [np.empty(0, np.uint8)], [np.empty(0, np.float32)]  # parts' dtypes
    for local, labels in chunks(src, cached, stats, made):
        if transform is not None:
            local = transform_points32(local, transform)
        if labels is not None:
            local, other, other_labels = _soil_apart(local, labels)
            i, z = _window_cells(other, plan.grid, win, None, keep_ids=True)
            o_ids.append(i[0])
            o_lab.append(other_labels[i[1]])
            o_z.append(z)
        i, z = _window_cells(local, plan.grid, win, offsets)
        ids.append(i)
        zs.append(z)
    z = np.concatenate(zs).astype(np.float64)  # float32 local heights, as in-process
    heights = cell_heights(np.concatenate(ids), z, shape, plan.statistic, full=True)
    others = None
    if rule is not None:
        others = nonsoil_sums(*(np.concatenate(parts) for parts in (o_ids, o_lab, o_z)), shape)
    dem = finish_epoch(heights, offsets.means(heights[1], plan.grid.cell), others, rule)
    arrays = {n: getattr(dem, f.name) for n, f in zip(EPOCH_ARRAYS, fields(EpochDEM), strict=False)}  # field order
    return [np.zeros(shape) if a is None else a.astype(np.int32) if n == "n" else a for n, a in arrays.items()]


def _soil_apart(local: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(soil points, other points, their labels) of a chunk in order: slices when soil comes first
    (as :func:`.scan.native_scan` keeps a tile), else a mask (a third of a task's time on 4 M points)."""
    soil = labels == 0
    k = int(np.count_nonzero(soil))
    if soil[:k].all():
        return local[:k], local[k:], labels[k:]
    return local[soil], local[~soil], labels[~soil]


def _file_chunks(plan: Plan, epoch: int, win: Window, keep, stats: dict) -> tuple:
    """(the epoch's source where it can meet the window, a function making its file chunks what
    the grid takes, as a :class:`.pointcache.KeptTile`: labelled, boxed, local, cropped by ``keep``)."""
    rule, ground = plan.rules[epoch], plan.ground[epoch]
    crs, src, box = window_source(plan, epoch, win)
    to_local = _local(crs, plan.frame, plan.origin, (plan.before, plan.after)[epoch])

    def made(file_chunks):
        for xyz, cls, sig in file_chunks:
            stats["read"] += len(xyz)
            labels = rule.labels(cls, sig) if rule is not None else None
            sel = cls == GROUND if rule is None and ground and cls is not None else None
            if box is not None:  # the box has a margin: cells are assigned exactly below
                near = in_box(xyz, *box)
                sel = near if sel is None else sel & near
            if sel is not None:
                xyz, labels = xyz[sel], None if labels is None else labels[sel]
            local = to_local(xyz)
            yield kept_chunk(local, labels, None if keep is None else keep(local))

    return src, made


def _window_cells(xyz32: np.ndarray, grid: GridSpec, win: Window, offsets: OffsetSums | None, keep_ids: bool = False):
    """Flat cell ids (on the whole grid's cells) and heights of the points on the window; positions
    in their cells added to ``offsets`` (if any); ``keep_ids``: ids with their points' indices."""
    lib = native.kernels() if offsets is not None and not keep_ids and xyz32.dtype == np.float32 else None
    # soil points on the kernel (sv_cells), bit for bit: the chunk's offsets summed from zero, then added
    if lib is not None:
        ids, z = np.empty(len(xyz32), np.int64), np.empty(len(xyz32), np.float64)
        sx, sy = np.zeros_like(offsets.sx), np.zeros_like(offsets.sy)
        m = native_cells(lib, xyz32, grid, win, ids, z, sx, sy)
        offsets.sx += sx
        offsets.sy += sy
        return ids[:m], z[:m]
    fcol, frow, ok = cell_coords(xyz32, grid, win)
    fcol, frow = fcol[ok], frow[ok]
    ids = frow.astype(np.int32)  # the cell's row and column: the coordinates truncated, as flat_ids
    ids -= win[0]
    ids *= win[3] - win[2]
    ids += fcol.astype(np.int32)
    ids -= win[2]
    if offsets is not None:
        offsets.add(ids, fcol, frow)
    return ((ids, np.flatnonzero(ok)) if keep_ids else ids), xyz32[ok, 2]


def _read_box(plan: Plan, crs, win: Window, transform) -> tuple[np.ndarray, np.ndarray] | None:
    """The x/y box (file CRS) a tile's points can come from, for files in the frame's CRS and
    metres (else None: read all); ``transform``: the file's local points to the grid."""
    if not (crs.equals(plan.frame.crs) and plan.frame.xy_unit == 1.0 and z_unit(crs) == 1.0):
        return None
    g, o = plan.grid, plan.origin
    x0, x1 = g.xmin + win[2] * g.cell - o[0], g.xmin + win[3] * g.cell - o[0]
    y0, y1 = g.ymax - win[1] * g.cell - o[1], g.ymax - win[0] * g.cell - o[1]
    corners = np.array([[x, y, 0.0] for x in (x0, x1) for y in (y0, y1)])
    margin = g.cell
    if transform is not None:  # back into the file's frame: the inverse rigid transform
        r, t = transform[:3, :3], transform[:3, 3]
        corners = (corners - t) @ r
        margin += 0.02 * (x1 - x0 + y1 - y0) + 1.0  # tilt of the unknown z
    return corners[:, :2].min(axis=0) - margin + o[:2], corners[:, :2].max(axis=0) + margin + o[:2]
