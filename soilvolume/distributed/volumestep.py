"""The driver's side of the tiled volume step (see :mod:`volumetiles`): grid the tiles into the
store with an overview, run the volume step on the overview, then on every tile, and write
the outputs from the store."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..dem.grid import MASK_LAYER, UINT8_LAYERS, EpochDEM
from ..reporting.report import build_report
from ..volumes.zones import check_inside
from ..workflow.steps import add_quality, alternative_move, planes_and_volumes
from . import overview
from .cog import write_outputs
from .tilestore import TileStore
from .tiletask import TILE_ARRAYS, map_tiles
from .volumetiles import VolumeJob, combine, grid_tile_stored, summarize_grid_tile, volume_tile


def tiled_volume_step(c, plan, store: TileStore, k: int, run: tuple, out: OutputDir, options, timer, hooks: Hooks):
    """(report, task stats, report.html arguments) of a run whose volume step goes tile by tile,
    its tiles kept in ``store``; ``run`` = (prepared pair, registration, registered after subset)."""
    prep, reg, after_thin = run
    grid, windows = plan.grid, list(store.windows)
    with timer("grids"):
        epochs, medians, stats = _grid_tiles(c, plan, store, k, hooks)
    hooks.step(70, f"estimating the vertical bias correction on a {k} x {k} overview of the grid")
    coarse = overview.coarse(grid, k)
    over, p_b, p_a = planes_and_volumes(prep, reg, coarse, *epochs, after_thin, options, timer, hooks)
    job = VolumeJob(
        store, grid, options, k, over.offset, over.stable, over.params, medians, (p_b, p_a), alternative_move(reg)
    )
    job = replace(job, rules=prep.rules)
    with timer("volume"):
        tiles = list(map_tiles(c, volume_tile, job, windows, hooks=hooks, steps=(75, 85, "volumes of")))
        order = {w: i for i, w in enumerate(windows)}
        tiles.sort(key=lambda t: order[t["window"]])  # the same sums whatever the finishing order
        vols = combine(tiles, over, grid.cell, k)
        if options.zones:
            check_inside(vols.zones, options.zones)
    hooks.step(85, "writing outputs (COG)")
    with timer("write"):
        write_outputs(out, _reader(store), grid, float(prep.origin[2]), options.correction)
    with timer("report"):
        report = build_report(prep, reg, grid, vols, p_b, p_a, options, timer)
        add_quality(report, vols, coarse, options, hooks)
    return report, stats, (vols, coarse, epochs[0].heights + prep.origin[2])


def _grid_tiles(c, plan, store: TileStore, k: int, hooks: Hooks):
    """Grid every tile into ``store`` (tiles already there are summarized, not run again):
    ((after, before) DEMs of the overview, (after, before) median counts, stats)."""
    coarse = overview.coarse(plan.grid, k)
    sums = [tuple(np.zeros((coarse.rows, coarse.cols)) for _ in range(3)) for _ in range(2)]
    hists = [np.zeros(overview.COUNT_CAP + 1, np.int64) for _ in range(2)]
    stats = {"read": 0, "seconds": 0.0}

    def add(summary) -> None:
        _, blocks, hist = summary[:3]
        for e in range(2):
            overview.add_blocks(sums[e], blocks[e])
            hists[e] += hist[e]

    todo = [w for w in store.windows if not store.has(TILE_ARRAYS, w)]
    for w in store.windows:
        if w not in todo:
            add(summarize_grid_tile(w, [store.load(n, w) for n in TILE_ARRAYS], k))
    for summary in map_tiles(c, grid_tile_stored, plan, todo, store, k, hooks=hooks, total=len(store.windows)):
        add(summary)
        for key in ("read", "seconds"):
            stats[key] += summary[3][key]
    stats["resumed"] = len(store.windows) - len(todo)
    epochs = []
    for total, valid, count in sums:  # block means; no per-cell spread (the LoD is the stable ground's)
        with np.errstate(invalid="ignore", divide="ignore"):
            heights = np.where(valid > 0, total / valid, np.nan)
        epochs.append(EpochDEM(heights, count.astype(np.int64), np.zeros(heights.shape)))
    medians = (overview.median_from_histogram(hists[0]), overview.median_from_histogram(hists[1]))
    return tuple(epochs), medians, stats


def _reader(store: TileStore):
    def get(key: str, rows: slice, cols: slice) -> np.ndarray:
        win = (rows.start, rows.stop, cols.start, cols.stop)
        if key in UINT8_LAYERS:  # the refilled mask, the classes: no NaN to fill with
            return store.read(key, win, fill=0, dtype=bool if key == MASK_LAYER else np.uint8)
        return store.read(key, win)

    return get
