"""One tile of the shared grid as a Dask task: both epochs' points on the tile's cells (read only
where they can meet it), their heights, counts and spreads with :func:`grid.cell_heights` on the
*global* grid's cell assignment; the tiling of the grid; running the tiles with resume."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..core.cells import in_box
from ..core.hooks import Hooks
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
from ..inputs.crs import WorkFrame
from ..inputs.footprint import PolygonMask
from ..inputs.io import GROUND
from ..inputs.prepare import _local
from ..inputs.stream import open_source
from .pointcache import chunks, kept_chunk
from .tilestore import TileStore

# a task's peak per point of its tile (both epochs, ids, sort keys, chunk): measured 22 B (a
# 73 M-point tile of the 256 M-point VPC pair peaked at 1.6 GB), counted twice over
TILE_BYTES_PER_POINT = 48.0
SCATTER_S = 60  # sending a run's plan to every worker
MIN_TILE, MAX_TILE = 16, 4096  # tile side (cells): small tiles keep very dense data within a task's memory
TILE_ARRAYS = tuple(f"{k}_{e}" for e in "ab" for k in EPOCH_ARRAYS)  # what a tile task returns: h_a, n_a, ...


def empty_value(name: str) -> float:
    """A tile array's value where no point fell: 0 for counts and centre offsets, NaN for heights
    and spreads."""
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


Window = tuple[int, int, int, int]  # r0, r1, c0, c1
OPENED = ("sources", "mask")  # the Plan's fields derived from the others and the inputs


def plan_parts(plan: Plan, windows: list[Window], k: int) -> dict:
    """What of a run's plan its tiles depend on, beyond its inputs and options: the frame, the
    grid, the registration (to 12 decimals), the crop, the tiling and the overview factor."""
    from dataclasses import fields

    parts = {f.name: getattr(plan, f.name) for f in fields(plan) if f.name not in ("before", "after", *OPENED)}
    parts.update(frame=plan.frame.wkt, grid=repr(plan.grid), transform=np.round(plan.transform, 12))
    parts.update(windows=windows, overview=k)
    return parts


def grid_tile(plan: Plan, win: Window, cached: tuple = (None, None)) -> tuple[Window, tuple[np.ndarray, ...], dict]:
    """(window, arrays of :data:`TILE_ARRAYS`, stats) of one tile: both epochs' points on its
    cells, their heights, counts, spreads and offsets from the cell centres; stats: points read,
    seconds. ``cached``: (before, after) {path: KeptTile} of VPC tiles in memory (:mod:`.pointcache`)."""
    import time

    t0, stats = time.perf_counter(), {"read": 0, "cached": 0}
    before = _epoch(plan, 0, win, crop_mask(plan), stats, cached[0])
    after = _epoch(plan, 1, win, None, stats, cached[1])
    stats["seconds"] = time.perf_counter() - t0
    arrays = tuple(
        a.astype(np.int32) if k == "n" else a for e in (after, before) for k, a in zip(EPOCH_ARRAYS, e, strict=True)
    )
    return win, arrays, stats


def window_source(plan: Plan, epoch: int, win: Window) -> tuple:
    """(CRS, source read only where it can meet the window, its x/y box or None) of one epoch
    (0 before, 1 after)."""
    from dataclasses import replace

    import pyproj

    crs = pyproj.CRS.from_wkt((plan.crs_b, plan.crs_a)[epoch])
    src = plan.sources[epoch] or open_source((plan.before, plan.after)[epoch])
    src = replace(src, index=plan.index[epoch])
    box = _read_box(plan, crs, win, plan.transform if epoch else None)
    return crs, (src if box is None else src.within(*box)), box


def _epoch(plan: Plan, epoch: int, win: Window, keep, stats: dict, cached: dict | None = None):
    """Heights, counts, spreads and centre offsets of one epoch (0 before, 1 after) on the
    window's cells; ``cached``: {path: KeptTile} of the epoch's VPC tiles in memory."""
    from ..registration.rigid import transform_points32

    transform = plan.transform if epoch else None
    shape = (win[1] - win[0], win[3] - win[2])
    ids, zs, offsets = [], [], OffsetSums(shape[0] * shape[1])
    rule, made = plan.rules[epoch], _FileChunks(plan, epoch, win, keep, stats)
    if rule is None and plan.ground[epoch]:
        cached = None  # kept tiles hold every class: class 2 is chosen from the files' classes
    o_ids, o_lab, o_z = [], [], []
    for local, labels in chunks(made.src, cached, stats, made):
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
    heights = cell_heights(np.concatenate(ids), z, shape, plan.statistic, spread=True, skew=True)
    others = None
    if rule is not None:
        others = nonsoil_sums(_joined(o_ids, np.int32), _joined(o_lab, np.uint8), _joined(o_z, np.float32), shape)
    dem = finish_epoch(heights, offsets.means(heights[1], plan.grid.cell), others, rule)
    zero = np.zeros(shape)
    names = [f.name for f in fields(EpochDEM)][: len(EPOCH_ARRAYS)]
    return tuple(zero if a is None else a for a in (getattr(dem, n) for n in names))


def _soil_apart(local: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(soil points, other points, their labels) of a chunk, each in the chunk's order: slices
    when its soil points come first (as the native scan keeps a tile,
    :mod:`.nativescan`), else by a mask (a third of a grid task's time on 4 M points)."""
    soil = labels == 0
    k = int(np.count_nonzero(soil))
    if soil[:k].all():
        return local[:k], local[k:], labels[k:]
    return local[soil], local[~soil], labels[~soil]


class _FileChunks:
    """File chunks (xyz, classification, signals) of one epoch made what the grid takes, (local
    float32 xyz, labels or None), as the first pass keeps them (:class:`.pointcache.KeptTile`):
    labelled, within the window's read box, in the local frame, cropped by ``keep``; ``src``: the
    epoch's source read only where it can meet the window."""

    def __init__(self, plan: Plan, epoch: int, win: Window, keep, stats: dict) -> None:
        self.rule, self.ground, self.keep, self.stats = plan.rules[epoch], plan.ground[epoch], keep, stats
        crs, self.src, self.box = window_source(plan, epoch, win)
        self.to_local = _local(crs, plan.frame, plan.origin, (plan.before, plan.after)[epoch])

    def __call__(self, file_chunks):
        rule, box, keep = self.rule, self.box, self.keep
        for xyz, cls, sig in file_chunks:
            self.stats["read"] += len(xyz)
            labels = rule.labels(cls, sig) if rule is not None else None
            sel = cls == GROUND if rule is None and self.ground and cls is not None else None
            if box is not None:  # the box has a margin: cells are assigned exactly below
                near = in_box(xyz, *box)
                sel = near if sel is None else sel & near
            if sel is not None:
                xyz, labels = xyz[sel], None if labels is None else labels[sel]
            local = self.to_local(xyz)
            yield kept_chunk(local, labels, None if keep is None else keep(local))


def _joined(parts: list, dtype) -> np.ndarray:
    return np.concatenate(parts) if parts else np.empty(0, dtype)


def _window_cells(xyz32: np.ndarray, grid: GridSpec, win: Window, offsets: OffsetSums | None, keep_ids: bool = False):
    """Flat cell ids within the window, and heights, of the points on the window's cells of
    ``grid`` (cells assigned on the whole grid, exactly as in-process); their positions in
    their cells are added to ``offsets`` (None: not needed, as for the points that are not
    soil). ``keep_ids``: the ids come with the indices of the points they belong to."""
    if offsets is not None and not keep_ids and xyz32.dtype == np.float32:
        from ..native import kernels

        lib = kernels()
        if lib is not None:
            return _native_window_cells(lib, xyz32, grid, win, offsets)
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


def _native_window_cells(lib, xyz32: np.ndarray, grid: GridSpec, win: Window, offsets: OffsetSums) -> tuple:
    """:func:`_window_cells` of soil points on the kernel (``sv_cells``): the same ids, heights
    and offset sums, bit for bit (the chunk's offsets summed from zero, then added, as
    :meth:`OffsetSums.add` does)."""
    ids, z = np.empty(len(xyz32), np.int64), np.empty(len(xyz32), np.float64)
    sx, sy = np.zeros_like(offsets.sx), np.zeros_like(offsets.sy)
    m = native_cells(lib, xyz32, grid, win, ids, z, sx, sy)
    offsets.sx += sx
    offsets.sy += sy
    return ids[:m], z[:m]


def _read_box(plan: Plan, crs, win: Window, transform) -> tuple[np.ndarray, np.ndarray] | None:
    """The x/y box (file CRS) a tile's points can come from, for files in the frame's CRS and
    metres (else None: read everything); ``transform`` maps the file's local points to the grid."""
    from ..inputs.crs import z_unit

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
    lo, hi = corners[:, :2].min(axis=0) - margin + o[:2], corners[:, :2].max(axis=0) + margin + o[:2]
    return lo, hi


def tiles(
    grid: GridSpec, side: int, align: float | None = None, corner: tuple[float, float] = (0.0, 0.0)
) -> list[Window]:
    """The grid cut into tiles of ``side`` x ``side`` cells (row-major); with ``align`` (metres),
    tile edges fall on ``corner`` (absolute x, y) plus multiples of it (the input's own tiling:
    each data tile is then read by one task), slivers merged into their neighbours."""
    r_off = c_off = 0
    if align:
        c_off = round(((corner[0] - grid.xmin) % align) / grid.cell) % side
        r_off = round(((grid.ymax - corner[1]) % align) / grid.cell) % side
    rows, cols = _edges(grid.rows, r_off, side), _edges(grid.cols, c_off, side)
    return [
        (r0, r1, c0, c1) for r0, r1 in zip(rows, rows[1:], strict=False) for c0, c1 in zip(cols, cols[1:], strict=False)
    ]


def _edges(n: int, offset: int, side: int) -> list[int]:
    """0, offset, offset + side, ..., n, without edges closer than side / 4 to the next."""
    inner = [e for e in range(offset, n, side) if e > 0]
    edges = [0]
    for e in inner:
        if e - edges[-1] >= side // 4 and n - e >= side // 4:
            edges.append(e)
    return edges + [n]


def run_tiles(
    c,
    plan: Plan,
    windows: list[Window],
    hooks: Hooks,
    store: TileStore | None = None,
    stats: dict | None = None,
    cache=None,
) -> tuple[np.ndarray, ...]:
    """Run every tile on the client ``c`` and assemble the arrays of :data:`TILE_ARRAYS` on the
    grid (:func:`epoch_dems` makes them the two epochs' DEMs). Tiles found in ``store`` (from an
    interrupted run of the same computation) are not run again; finished tiles are saved there.
    ``stats`` sums the tasks' points read (``cached``: of those, taken from the workers' memory)
    and seconds; ``cache``: the first pass's tiles on the workers (:class:`.pointcache.PointCache`)."""
    stats = stats if stats is not None else {}
    stats.update(read=0, cached=0, seconds=0.0, resumed=0)
    g = plan.grid
    out = tuple(np.full((g.rows, g.cols), empty_value(k), np.int64 if k[0] == "n" else float) for k in TILE_ARRAYS)
    todo = []
    for win in windows:
        if store is not None and store.has(TILE_ARRAYS, win):
            _place(out, win, [store.load(k, win) for k in TILE_ARRAYS])
        else:
            todo.append(win)
    per = window_caches(plan, todo, cache)
    for win, arrays, task in map_tiles(c, grid_tile, plan, todo, hooks=hooks, total=len(windows), per=per):
        for key in ("read", "cached", "seconds"):
            stats[key] += task[key]
        _place(out, win, arrays)
        if store is not None:
            store.save(win, dict(zip(TILE_ARRAYS, arrays, strict=True)))
    stats["resumed"] = len(windows) - len(todo)
    return out


def window_caches(plan: Plan, windows: list[Window], cache) -> list | None:
    """Per window, the (before, after) {path: future} of the cached VPC tiles its reads open
    (None without a cache)."""
    if cache is not None:
        cache.arrived()  # tiles the driver read while the cluster started
    if cache is None or not cache.futures:
        return None
    crops = (crop_mask(plan).key(), None)  # the before is kept cropped, the after whole
    return [tuple(cache.meeting(window_source(plan, e, w)[1], crops[e]) for e in (0, 1)) for w in windows]


def map_tiles(
    c, fn, shared, windows: list[Window], *args, hooks: Hooks, total: int = 0, steps=(55, 70, "gridded"), per=None
):
    """``fn(shared, window, *args[, per[i]])`` for every window as Dask tasks on the client ``c``
    (``shared`` sent to the workers once, not with every task), yielding the results as tasks
    finish, with progress from ``steps[0]`` to ``steps[1]`` %. ``total``: the tiles of the run,
    when those not in ``windows`` were done by an earlier run; ``per``: one more argument per
    window (futures in it resolved on the worker)."""
    from .cluster import checker, completed

    if len(windows) < total:
        hooks.step(steps[0], f"resuming: {total - len(windows)} of {total} tiles done in an earlier run")
    if not windows:
        return
    n, (lo, hi, verb) = len(windows), steps
    ref = c.scatter(shared, broadcast=True, timeout=SCATTER_S)
    lists = [[a] * n for a in args] + ([per] if per is not None else [])
    futures = c.map(fn, [ref] * n, windows, *lists, pure=False)
    for k, result in enumerate(completed(c, futures, f"the tiles were being {verb}", checker(hooks)), 1):
        hooks.step(lo + (hi - lo) * k / n, f"{verb} tile {k}/{n}")
        yield result


def epoch_dems(arrays: tuple[np.ndarray, ...], rules: tuple = (None, None)) -> tuple[EpochDEM, EpochDEM]:
    """(after, before) DEMs from the arrays of :data:`TILE_ARRAYS`, in that order; ``rules``:
    the (before, after) point rules that labelled them (:attr:`Plan.rules`)."""
    from dataclasses import replace

    k = len(EPOCH_ARRAYS)
    return replace(EpochDEM(*arrays[:k]), rule=rules[1]), replace(EpochDEM(*arrays[k:]), rule=rules[0])


def _place(out: tuple[np.ndarray, ...], win: Window, arrays) -> None:
    r0, r1, c0, c1 = win
    for full, part in zip(out, arrays, strict=True):
        full[r0:r1, c0:c1] = part
