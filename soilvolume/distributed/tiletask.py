"""The tiling of the shared grid and the running of its tiles (:mod:`.gridtile`) on a Dask
client, with progress and resume from a run's tile store."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from ..core.hooks import Hooks
from ..core.types import GridSpec
from ..dem.grid import EPOCH_ARRAYS, EpochDEM
from .cluster import checker
from .gridtile import TILE_ARRAYS, Plan, crop_mask, empty_value, grid_tile, window_source
from .tilestore import TileStore, Window
from .waiting import completed

SCATTER_S = 60  # sending a run's plan to every worker
MIN_TILE, MAX_TILE = 16, 4096  # tile side (cells): small tiles keep very dense data within a task's memory


OPENED = ("sources", "mask")  # the Plan's fields derived from the others and the inputs


def plan_parts(plan: Plan, windows: list[Window], k: int) -> dict:
    """What of a run's plan its tiles depend on, beyond its inputs and options: the frame, the
    grid, the registration (to 12 decimals), the crop, the tiling and the overview factor."""
    parts = {f.name: getattr(plan, f.name) for f in fields(plan) if f.name not in ("before", "after", *OPENED)}
    parts.update(frame=plan.frame.wkt, grid=repr(plan.grid), transform=np.round(plan.transform, 12))
    parts.update(windows=windows, overview=k)
    return parts


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
    k = len(EPOCH_ARRAYS)
    return replace(EpochDEM(*arrays[:k]), rule=rules[1]), replace(EpochDEM(*arrays[k:]), rule=rules[0])


def _place(out: tuple[np.ndarray, ...], win: Window, arrays) -> None:
    r0, r1, c0, c1 = win
    for full, part in zip(out, arrays, strict=True):
        full[r0:r1, c0:c1] = part
