"""The driver's side of the tiled volume step (see :mod:`volumetiles`; the order is
:mod:`soilvolume.workflow.steps`'): grid the tiles into the store with an overview, then, given
the volume step of the overview, the volume step on every tile; the outputs are read from the
store."""

from __future__ import annotations

from itertools import chain

import numpy as np

from ..core.hooks import Hooks
from ..dem.grid import MASK_LAYER, UINT8_LAYERS, EpochDEM
from ..volumes.zones import check_inside
from . import overview
from .tilestore import TileStore
from .tiletask import add_stats, kept_and_todo, map_tiles, window_caches
from .volumetiles import VolumeJob, combine, grid_tile_stored, summarize_grid_tile, volume_tile


def tile_volumes(c, job: VolumeJob, over, hooks: Hooks, steps: tuple):
    """The volume step tile by tile on the workers, given the correction ``over`` found on the
    overview (the volume step of the overview grid, in ``job``), combined into the grid's
    ``Volumes``; progress ``steps`` = (start %, end %, message)."""
    windows = list(job.store.windows)
    tiles = list(map_tiles(c, volume_tile, job, windows, hooks=hooks, steps=steps))
    order = {w: i for i, w in enumerate(windows)}
    tiles.sort(key=lambda t: order[t["window"]])  # the same sums whatever the finishing order
    vols = combine(tiles, over, job.grid.cell, job.k)
    if job.options.zones:
        check_inside(vols.zones, job.options.zones)
    return vols


def grid_tiles(c, plan, store: TileStore, k: int, hooks: Hooks, cache=None):
    """Grid every tile into ``store`` (tiles already there are summarized, not run again):
    ((after, before) DEMs of the overview, (after, before) median counts, stats)."""
    coarse = overview.coarse(plan.grid, k)
    sums = [tuple(np.zeros((coarse.rows, coarse.cols)) for _ in range(3)) for _ in range(2)]
    hists = [np.zeros(overview.COUNT_CAP + 1, np.int64) for _ in range(2)]
    kept, todo = kept_and_todo(store, store.windows)
    stats = {"read": 0, "cached": 0, "seconds": 0.0, "resumed": len(kept)}
    done = [summarize_grid_tile(w, arrays, k) for w, arrays in kept]
    per = window_caches(plan, todo, cache)
    tasks = map_tiles(c, grid_tile_stored, plan, todo, store, k, hooks=hooks, total=len(store.windows), per=per)
    for _, blocks, hist, *task in chain(done, tasks):
        for e in range(2):
            overview.add_blocks(sums[e], blocks[e])
            hists[e] += hist[e]
        if task:
            add_stats(stats, task[0])
    epochs = []
    for total, valid, count in sums:  # block means; no per-cell spread (the LoD is the stable ground's)
        with np.errstate(invalid="ignore", divide="ignore"):
            heights = np.where(valid > 0, total / valid, np.nan)
        epochs.append(EpochDEM(heights, count.astype(np.int64), np.zeros(heights.shape)))
    medians = (overview.median_from_histogram(hists[0]), overview.median_from_histogram(hists[1]))
    return tuple(epochs), medians, stats


def reader(store: TileStore):
    def get(key: str, rows: slice, cols: slice) -> np.ndarray:
        win = (rows.start, rows.stop, cols.start, cols.stop)
        if key in UINT8_LAYERS:  # the refilled mask, the classes: no NaN to fill with
            return store.read(key, win, fill=0, dtype=bool if key == MASK_LAYER else np.uint8)
        return store.read(key, win)

    return get
