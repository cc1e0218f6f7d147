"""The volume step of a grid too large for one process, tile by tile (``--volume-step tiles``):

1. The gridding tasks keep their tiles on disk (:class:`TileStore`) and return the block sums of
   an overview of the grid (:mod:`tiletask`) and their count histograms.
2. The driver runs the volume step on the overview (cells k times larger): stable ground, the
   correction and the paper's planes found over the whole site, as in-process; each epoch's
   median point count from the histograms.
3. One task per tile runs the volume step on its window plus a halo, given that correction and
   stable ground on its cells (:class:`soilvolume.volumes.compute.Given`); its own stable
   residuals give its LoD and error model. Budgets are summed over the tiles' cores; each part's
   half-width combines, as in-process: the error model (the tiles' semivariograms pooled) over
   the part's whole area, correlated across tile edges; the systematic terms summed (refilled
   share, leftover bias); the independent ones in quadrature (refill errors, small detections);
   what every tile shares: the overview's correction bias and the other registration pose.
4. Outputs are COGs written block by block from the tiles on disk (:func:`reader`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compensation.planes import plane_offset
from ..core.hooks import Hooks
from ..core.types import GridSpec
from ..dem.grid import MASK_LAYER, UINT8_LAYERS, EpochDEM
from ..options import Options
from ..volumes import coverage
from ..volumes.compute import Given, Volumes, compute_volumes
from ..volumes.uncertainty import TERMS, region_sigma, widen, z_value
from ..volumes.zones import check_inside
from .gridtile import TILE_ARRAYS, empty_value
from .tilestore import TileStore, Window
from .tiletask import COUNT_CAP, add_blocks, coarse, epoch_dems, grid_stored, map_tiles, median_from_histogram, to_cells

HALO_CELLS, HALO_M = 16, 5.0  # context around a tile (change areas, refills, buffers): the larger
VOLUME_ARRAYS = ("dem_out_a", "dem_out_b", "diff", "offset", "filled_mask", "classes")
BUDGETS = ("compensated", "all_cells", "uncompensated", "paper_plane", "thresholded", "holes")
PARTS = ("net", "cut", "fill", "net_compared_area")


def halo(cell: float) -> int:
    """Cells of context around a tile: ``HALO_CELLS``, or ``HALO_M`` metres on fine grids."""
    return max(HALO_CELLS, int(np.ceil(HALO_M / cell)))


@dataclass(frozen=True)
class VolumeJob:
    """What a volume tile task needs (picklable)."""

    store: TileStore
    grid: GridSpec
    options: Options
    k: int
    offset: np.ndarray  # the overview's correction surface
    stable: np.ndarray  # the overview's stable ground
    params: dict
    medians: tuple[float, float]  # (after, before) median point counts of the whole grid
    planes: tuple  # (before, after) RANSAC planes of the paper
    moved: np.ndarray | None
    rules: tuple = (None, None)  # (before, after) point rules (Plan.rules)


def volume_tile(job: VolumeJob, win: Window) -> dict:
    """The volume step on one tile with its halo, its core's arrays kept in the store: its budgets
    and uncertainty."""
    g = job.grid
    r0, r1, c0, c1 = win
    h = halo(g.cell)
    ext = (max(0, r0 - h), min(g.rows, r1 + h), max(0, c0 - h), min(g.cols, c1 + h))
    a = [job.store.read(n, ext, fill=empty_value(n)) for n in TILE_ARRAYS]
    wgrid = g.window(*ext)
    core = (slice(r0 - ext[0], r1 - ext[0]), slice(c0 - ext[2], c1 - ext[2]))
    stable = to_cells(job.stable, job.k, ext, nearest=True).astype(bool)
    given = Given(to_cells(job.offset, job.k, ext), stable, job.params, job.medians, core)
    d_i = plane_offset(job.planes[0], job.planes[1], wgrid)
    after, before = epoch_dems(a, job.rules)
    vols = compute_volumes(after, before, d_i, wgrid, job.options, job.moved, given)
    job.store.save(win, {n: getattr(vols, n)[core] for n in VOLUME_ARRAYS})
    out = {b: getattr(vols, b) for b in BUDGETS}
    edges = (ext[0] == 0, ext[1] == g.rows, ext[2] == 0, ext[3] == g.cols)  # the grid's edge: top, bottom, left, right
    out.update(
        window=win,
        uncertainty=vols.uncertainty,
        zones=vols.zones,
        empty=(vols.empty_cells, vols.empty_before, vols.empty_after),
        coverage=coverage.counts(
            after.counts, before.counts, vols.filled_mask, vols.diff, after.all_points(), core, edges
        ),
    )
    return out


def _sum_dicts(dicts: list[dict]) -> dict:
    keys = [k for k, v in dicts[0].items() if isinstance(v, int | float)]
    return {k: type(dicts[0][k])(sum(d[k] for d in dicts)) for k in keys}


def _zones(tiles: list[dict]) -> list[dict]:
    out = []  # none when the run has no zones (each tile's list empty)
    for rows in zip(*(t["zones"] for t in tiles), strict=True):
        same = {k: rows[0][k] for k in ("polygon_area_m2", "repaired") if k in rows[0]}  # each tile's whole polygon
        out.append({"id": rows[0]["id"], "name": rows[0]["name"], **_sum_dicts(list(rows)), **same})
    return out


def _weighted(tiles: list[dict], key: str, weights: np.ndarray, default: float) -> float:
    """The tiles' ``uncertainty[key]`` averaged with ``weights`` (``default`` when none is finite)."""
    v = np.array([t["uncertainty"][key] for t in tiles], float)
    ok = np.isfinite(v) & (weights > 0)
    return float(np.sum(v[ok] * weights[ok]) / weights[ok].sum()) if ok.any() else default


def combine(tiles: list[dict], over: Volumes, cell: float, k: int) -> Volumes:
    """The run's Volumes: budgets summed over the tiles, half-widths combined with the overview's
    (of ``k`` x ``k`` cells), the overview's rasters (the report's map, histogram and checks)."""
    budgets = {b: _sum_dicts([t[b] for t in tiles]) for b in BUDGETS}
    u = dict(over.uncertainty)
    z = z_value(over.uncertainty["confidence"])
    reg = {p: sum(t["uncertainty"]["registration_m3"][p] for t in tiles) for p in ("net", "cut", "fill")}
    reg["net_compared_area"] = reg["net"]
    w = np.array([t["uncertainty"]["stable_cells"] for t in tiles], float)  # the models pooled by stable cells
    model = {k: _weighted(tiles, f"{k}_{u}", w, 0.0) for k, u in (("nugget", "m2"), ("psill", "m2"), ("range", "m"))}
    u.update(nugget_m2=model["nugget"], psill_m2=model["psill"], range_m=model["range"])
    skirt = {p: sum(t["uncertainty"]["skirt_m3"][p] for t in tiles) for p in ("cut", "fill")}  # one-sided: summed
    skirt["net"] = abs(skirt["fill"] - skirt["cut"])
    for part in PARTS:
        area = sum(t["uncertainty"]["part_area_m2"][part] for t in tiles)
        region = region_sigma(round(area / cell**2), cell, model)  # correlated across tile edges too
        terms = [dict(zip(TERMS, t["uncertainty"]["terms_m3"][part], strict=True)) for t in tiles]
        # the refilled share and leftover bias are fully correlated across tiles; refill errors
        # and the extras (small detections) independent
        systematic = [sum(t[n] for t in terms) for n in ("refilled_share", "leftover_bias")] + [skirt.get(part, 0.0)]
        independent = [float(np.sqrt(sum(t[n] * t[n] for t in terms))) for n in ("refill_error", "extras")]
        shared = np.hypot(area * over.uncertainty["bias_sigma_m"], reg[part])  # the same in every tile
        u[part] = z * float(np.linalg.norm([region, *systematic, *independent, shared]))
    unclear = {p: sum(t["uncertainty"].get("unclassified_m3", {}).get(p, 0.0) for t in tiles) for p in ("cut", "fill")}
    unclear["net"] = max(unclear.values())  # as volumes/nonsoil: between net - fill and net + cut
    u.update(widen({p: u[p] for p in PARTS}, unclear), unclassified_m3=unclear)
    u["registration_m3"], u["skirt_m3"] = {p: reg[p] for p in ("net", "cut", "fill")}, skirt
    for key in ("marginal_detections_m3", "broad_m3"):  # each tile's in its extras: in quadrature
        per_tile = [t["uncertainty"][key] for t in tiles]
        u[key] = {p: float(np.sqrt(np.sum(np.square([m[p] for m in per_tile])))) for p in ("net", "cut", "fill")}
    cells = np.array([t["all_cells"]["cells"] for t in tiles], float)
    for key in ("lod_m", "sigma_m"):
        u[key] = _weighted(tiles, key, cells, over.uncertainty[key])
    u["volume_step"] = {"tiles": len(tiles), "overview_cell_factor": k}
    empty = np.sum([t["empty"] for t in tiles], axis=0)
    return over.with_(
        uncertainty=u,
        **budgets,
        empty_cells=int(empty[0]),
        empty_before=int(empty[1]),
        empty_after=int(empty[2]),
        zones=_zones(tiles),
        coverage=coverage.combine([t["coverage"] for t in tiles]),
    )


def tile_volumes(c, job: VolumeJob, over, hooks: Hooks, steps: tuple):
    """The grid's ``Volumes`` from the volume step tile by tile, given ``over``, the overview's
    (its correction in ``job``); progress ``steps`` = (start %, end %, message)."""
    windows = list(job.store.windows)
    tiles = list(map_tiles(c, volume_tile, job, windows, hooks=hooks, steps=steps))
    order = {w: i for i, w in enumerate(windows)}
    tiles.sort(key=lambda t: order[t["window"]])  # the same sums whatever the finishing order
    vols = combine(tiles, over, job.grid.cell, job.k)
    if job.options.zones:
        check_inside(vols.zones, job.options.zones)
    return vols


def grid_tiles(c, plan, store: TileStore, k: int, hooks: Hooks, cache=None):
    """Grid every tile into ``store`` (:func:`.tiletask.grid_stored`): ((after, before) DEMs of the
    overview, (after, before) median counts, stats)."""
    over = coarse(plan.grid, k)
    sums = [tuple(np.zeros((over.rows, over.cols)) for _ in range(3)) for _ in range(2)]
    hists = [np.zeros(COUNT_CAP + 1, np.int64) for _ in range(2)]
    stats: dict = {}
    for _, blocks, hist in grid_stored(c, plan, store, hooks, stats, cache, k):
        for e in range(2):
            add_blocks(sums[e], blocks[e])
            hists[e] += hist[e]
    epochs = []
    for total, valid, count in sums:  # block means; no per-cell spread (the LoD is the stable ground's)
        with np.errstate(invalid="ignore", divide="ignore"):
            heights = np.where(valid > 0, total / valid, np.nan)
        epochs.append(EpochDEM(heights, count.astype(np.int64), np.zeros(heights.shape)))
    medians = (median_from_histogram(hists[0]), median_from_histogram(hists[1]))
    return tuple(epochs), medians, stats


def reader(store: TileStore):
    """A window of an output array, read from the tile store."""

    def get(key: str, rows: slice, cols: slice) -> np.ndarray:
        win = (rows.start, rows.stop, cols.start, cols.stop)
        if key in UINT8_LAYERS:  # the refilled mask, the classes: no NaN to fill with
            return store.read(key, win, fill=0, dtype=bool if key == MASK_LAYER else np.uint8)
        return store.read(key, win)

    return get
