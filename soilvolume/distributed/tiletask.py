"""The grid cut into tiles (their size from the memory budget and the input's own tiling) and the
tiles run (:mod:`.gridtile`) on a Dask client, with progress and resume from a run's tile store.
The overview of a grid too large for one process: the k x k block sums the gridding tasks return,
the overview grid they add up to, each epoch's median point count from the tasks' count
histograms, the overview's correction brought back to cells."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import fields, replace
from itertools import pairwise

import numpy as np

from ..core.hooks import Hooks
from ..core.types import GridSpec
from ..dem.grid import EPOCH_ARRAYS, EpochDEM
from ..inputs.footprint import footprint, polygon_area
from ..options import Options
from .cluster import checker
from .gridtile import TILE_ARRAYS, Plan, crop_mask, empty_value, grid_tile, window_source
from .schedule import TILE_BYTES_PER_POINT, Schedule, budget_gb, check_tiles
from .tilestore import TileStore, Window
from .waiting import completed

SCATTER_S = 60  # sending a run's plan to every worker
MIN_TILE, MAX_TILE = 16, 4096  # tile side (cells): small tiles keep very dense data within a task's memory
TILE_POINTS = 32e6  # points per tile at most: ~1.3 GB per task; fewer reads of dense LAZ tiles
OPENED = ("sources", "mask")  # the Plan's fields derived from the others and the inputs
STATS = ("read", "cached", "seconds")  # what the tasks' stats add up
RASTER_BYTES_PER_CELL = 200.0  # the volume step's peak per grid cell (arrays, labels, solver)
COUNT_CAP = 1 << 16  # counts above this are one histogram bin (the median is far below)
MAX_CELLS = 2_000_000  # the overview's cells at most: its volume step runs in the driver (~50 s)


def data_tiling(src, cell: float, side: int) -> tuple[float, float, float] | None:
    """(pitch m, x, y of a tile corner) of a VPC's square tiling, snapped to ``cell``, when a grid
    tile can hold one data tile (else None). From the tiles' lower-left corners, not the header
    boxes' widths: those span the points (49.999 m in a 50 m tiling), and windows cut on a
    49.999 m pitch would cross every data tile, each then read by several tasks."""
    if src.vpc is None or len(src.vpc.tiles) < 2:
        return None
    lows = np.array([t.lo[:2] for t in src.vpc.tiles], float)
    steps = np.rint(lows / cell).astype(np.int64)  # corners in cells (a tile's first points sit at its corner)
    pitch = _mode(np.concatenate([np.diff(_shared(steps[:, k])) for k in (0, 1)]))
    if pitch is None or not 0 < pitch <= side:
        return None
    x0, y0 = (_mode(steps[:, k] % pitch) for k in (0, 1))
    return pitch * cell, x0 * cell, y0 * cell


def _shared(corners: np.ndarray) -> np.ndarray:
    """The corner coordinates (one axis) at least a median number of tiles share: a row or column
    of a tiling shares its edge, an edge tile whose points start inside it has its own."""
    v, n = np.unique(corners, return_counts=True)
    return v[n >= np.median(n)]


def _mode(values: np.ndarray) -> int | None:
    """The most common of ``values`` (the smallest on ties), None when there are none."""
    v, n = np.unique(values, return_counts=True)
    return int(v[np.argmax(n)]) if len(v) else None


def tile_windows(options: Options, grid: GridSpec, prep, schedule: Schedule, src) -> tuple:
    """(the tile windows, their side in cells, points per cell) of the run's grid; ``src``: the
    before source (its VPC's tiling)."""
    cell, workers = grid.cell, max(1, schedule.workers)
    area = [polygon_area(footprint(t[:, :2])) for t in (prep.before_thin, prep.after_thin)]
    used = [prep.inputs[e]["points_after_crop"] for e in ("before", "after")]
    density = sum(n / max(a, 1.0) for n, a in zip(used, area, strict=True)) * cell**2  # each epoch's over its footprint
    task_gb = budget_gb(options.memory_limit) / workers
    side = int(options.tile_cells)
    if side <= 0:  # what a task's memory holds, small enough for two tiles per worker
        area = min(TILE_POINTS, task_gb * 2**30 * 0.5 / TILE_BYTES_PER_POINT) / max(density, 1e-3)
        side = int(np.clip(math.sqrt(min(area, grid.rows * grid.cols / (2 * workers))), MIN_TILE, MAX_TILE))
    tiling = None if options.tile_cells else data_tiling(src, cell, 2 * side)
    if tiling and density * (tiling[0] / cell) ** 2 * TILE_BYTES_PER_POINT > 0.5 * task_gb * 2**30:
        tiling = None  # a data tile too dense for one task's memory: smaller tiles, read more than once
    windows = tiles(grid, side)
    if tiling:  # snap to the input's tiles (one grid tile per data tile) when that keeps the workers busy
        pitch = max(1, round(tiling[0] / cell))
        aligned = tiles(grid, pitch, tiling[0], tiling[1:])
        if len(aligned) >= min(len(windows), 2 * schedule.workers):
            windows, side = aligned, pitch
    check_tiles(windows, density, task_gb, options)
    return windows, side, density


def volume_factor(options: Options, grid: GridSpec) -> int:
    """1 for the volume step on the whole grid in the driver, else the block side of the
    overview the tiled volume step finds the correction on (``--volume-step``)."""
    k = factor(grid, budget_gb(options.memory_limit))
    if options.volume_step == "whole" or (options.volume_step == "auto" and k == 1):
        return 1
    return max(k, 2, blocks_for(grid, MAX_CELLS))  # the overview's volume step stays short


def plan_parts(plan: Plan, windows: list[Window], k: int) -> dict:
    """What of a run's plan its tiles depend on, beyond its inputs and options: the frame, the
    grid, the registration (to 12 decimals), the crop, the tiling and the overview factor."""
    parts = {f.name: getattr(plan, f.name) for f in fields(plan) if f.name not in ("before", "after", *OPENED)}
    parts.update(frame=plan.frame.wkt, grid=repr(plan.grid), transform=np.round(plan.transform, 12))
    parts.update(windows=windows, overview=k)
    return parts


def tiles(grid: GridSpec, side: int, align: float | None = None, corner: tuple = (0.0, 0.0)) -> list[Window]:
    """The grid cut into ``side`` x ``side`` tiles (row-major); with ``align`` (m), edges on ``corner``
    (x, y) plus multiples of it (the input's tiling: one task per data tile), slivers merged."""
    r_off = c_off = 0
    if align:
        c_off = round(((corner[0] - grid.xmin) % align) / grid.cell) % side
        r_off = round(((grid.ymax - corner[1]) % align) / grid.cell) % side
    rows, cols = _edges(grid.rows, r_off, side), _edges(grid.cols, c_off, side)
    return [(*r, *c) for r in pairwise(rows) for c in pairwise(cols)]


def _edges(n: int, offset: int, side: int) -> list[int]:
    """0, offset, offset + side, ..., n, without edges closer than side / 4 to the next."""
    edges = [0]
    for e in range(offset, n, side):
        if e > 0 and e - edges[-1] >= side // 4 and n - e >= side // 4:
            edges.append(e)
    return edges + [n]


def grid_tile_stored(plan: Plan, win: Window, store: TileStore, k: int, cached: tuple = (None, None)) -> tuple:
    """:func:`.gridtile.grid_tile` kept in ``store``: (:func:`summary` of the tile (``k`` > 1) or its
    window, stats)."""
    arrays, stats = grid_tile(plan, win, cached)
    store.save(win, arrays)
    return (summary(win, arrays, k) if k > 1 else win), stats


def summary(win: Window, a: dict, k: int) -> tuple:
    """(window, (after, before) block sums of the overview of ``k`` x ``k`` cells, their count histograms);
    ``a``: the tile's arrays by name."""
    blocks = tuple(block_sums(win, k, a[f"h_{e}"], a[f"n_{e}"]) for e in "ab")
    return win, blocks, tuple(count_histogram(a[f"n_{e}"]) for e in "ab")


def grid_stored(c, plan: Plan, store: TileStore, hooks: Hooks, stats: dict, cache=None, k: int = 1) -> Iterator:
    """Every tile of ``store`` not there yet (an interrupted run's are kept) gridded into it on ``c``:
    the :func:`grid_tile_stored` of each, the kept ones' first; ``stats``: points read (and from
    memory), seconds, tiles resumed."""
    kept = [store.has(TILE_ARRAYS, w) for w in store.windows]
    todo = [w for w, done in zip(store.windows, kept, strict=True) if not done]
    stats.update(dict.fromkeys(STATS, 0), resumed=sum(kept))
    for w, done in zip(store.windows, kept, strict=True):
        if done:
            yield summary(w, {n: store.load(n, w) for n in TILE_ARRAYS}, k) if k > 1 else w
    if stats["resumed"]:
        hooks.step(55, f"resuming: {stats['resumed']} of {len(store.windows)} tiles done in an earlier run")
    if cache is not None:
        cache.sent()  # tiles the driver read while the cluster started
    per = None  # per window, the (before, after) {path: future} of the cached VPC tiles its reads open
    if cache is not None and cache.futures:
        crops = (crop_mask(plan).key(), None)  # the before is kept cropped, the after whole
        per = [tuple(cache.meeting(window_source(plan, e, w)[1], crops[e]) for e in (0, 1)) for w in todo]
    for part, task in map_tiles(c, grid_tile_stored, plan, todo, store, k, hooks=hooks, per=per):
        for key in STATS:
            stats[key] += task[key]
        yield part


def run_tiles(c, plan: Plan, hooks: Hooks, store: TileStore, stats=None, cache=None) -> tuple[EpochDEM, EpochDEM]:
    """(after, before) DEMs of the grid, read from ``store`` once every tile is there (:func:`grid_stored`)."""
    for _ in grid_stored(c, plan, store, hooks, {} if stats is None else stats, cache):
        pass
    whole = (0, plan.grid.rows, 0, plan.grid.cols)
    arrays = [store.read(n, whole, empty_value(n), np.int64 if n[0] == "n" else float) for n in TILE_ARRAYS]
    return epoch_dems(arrays, plan.rules)


def map_tiles(c, fn, shared, windows: list[Window], *args, hooks: Hooks, steps=(55, 70, "gridded"), per=None):
    """``fn(shared, window, *args[, per[i]])`` for every window as Dask tasks on ``c`` (``shared``
    sent to the workers once), yielding results as tasks finish, progress from ``steps[0]`` to
    ``steps[1]`` %; ``per``: one more argument per window (futures in it resolved on the worker)."""
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
    """(after, before) DEMs from the arrays of :data:`TILE_ARRAYS`; ``rules``: the (before, after)
    point rules that labelled them (:attr:`Plan.rules`)."""
    k = len(EPOCH_ARRAYS)
    return replace(EpochDEM(*arrays[:k]), rule=rules[1]), replace(EpochDEM(*arrays[k:]), rule=rules[0])


def factor(grid: GridSpec, budget_gb: float) -> int:
    """The smallest power of 2 k whose k x k blocks bring the grid's volume step within half of
    the memory budget (1: the whole grid fits)."""
    return blocks_for(grid, budget_gb * 2**30 * 0.5 / RASTER_BYTES_PER_CELL)


def blocks_for(grid: GridSpec, cells: float) -> int:
    """The smallest power of 2 k with at most ``cells`` blocks of k x k grid cells."""
    k = 1
    while grid.rows * grid.cols / (k * k) > cells:
        k *= 2
    return k


def coarse(grid: GridSpec, k: int) -> GridSpec:
    """The overview grid: cells of k x k grid cells, from the same corner."""
    return replace(grid, cell=grid.cell * k, rows=math.ceil(grid.rows / k), cols=math.ceil(grid.cols / k))


def block_sums(win, k: int, h: np.ndarray, n: np.ndarray) -> tuple:
    """(first block row, first block col, (height sum, valid cells, count sum)) of a tile's k x k
    blocks on the grid's block lattice (blocks cut by tile edges get the rest from the next tile)."""
    r0, r1, c0, c1 = win
    br = np.arange(r0, r1) // k - r0 // k
    bc = np.arange(c0, c1) // k - c0 // k
    shape = (int(br[-1]) + 1, int(bc[-1]) + 1)
    ids = (br[:, None] * shape[1] + bc[None, :]).ravel()
    hv, nv = h.ravel(), n.ravel()
    ok = np.isfinite(hv)
    size = shape[0] * shape[1]
    sums = (
        np.bincount(ids[ok], hv[ok], minlength=size),
        np.bincount(ids[ok], minlength=size).astype(float),
        np.bincount(ids, nv.astype(float), minlength=size),
    )
    return r0 // k, c0 // k, tuple(s.reshape(shape) for s in sums)


def count_histogram(n: np.ndarray) -> np.ndarray:
    """Histogram of the non-zero point counts of a tile's cells (summed across tiles)."""
    has = n[n > 0]
    return np.bincount(np.minimum(has, COUNT_CAP).astype(np.int64), minlength=COUNT_CAP + 1)


def median_from_histogram(hist: np.ndarray) -> float:
    """``np.median`` of the values a histogram of integers counts (NaN when empty)."""
    total = int(hist.sum())
    if total == 0:
        return float("nan")
    cum = np.cumsum(hist)
    lo = int(np.searchsorted(cum, (total - 1) // 2 + 1))  # the (total-1)//2-th value (0-based)
    hi = int(np.searchsorted(cum, total // 2 + 1))
    return (lo + hi) / 2.0


def add_blocks(target: tuple[np.ndarray, ...], part: tuple) -> None:
    """Add one tile's :func:`block_sums` into the overview's (sum, valid, count) arrays."""
    b0, c0, sums = part
    for full, s in zip(target, sums, strict=True):
        full[b0 : b0 + s.shape[0], c0 : c0 + s.shape[1]] += s


def to_cells(values: np.ndarray, k: int, win, nearest: bool = False) -> np.ndarray:
    """An overview raster on the cells of window ``win``: bilinear between block centres (NaN
    blocks take their nearest finite block's value first), or ``nearest`` the block's value."""
    from scipy import ndimage

    r0, r1, c0, c1 = win
    if nearest:
        return values[np.arange(r0, r1)[:, None] // k, np.arange(c0, c1)[None, :] // k]
    v = np.asarray(values, float)
    bad = ~np.isfinite(v)
    if bad.all():
        return np.zeros((r1 - r0, c1 - c0))
    if bad.any():
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        v = v[tuple(idx)]
    rr = (np.arange(r0, r1) + 0.5) / k - 0.5
    cc = (np.arange(c0, c1) + 0.5) / k - 0.5
    coords = np.meshgrid(rr, cc, indexing="ij")
    return ndimage.map_coordinates(v, coords, order=1, mode="nearest")
