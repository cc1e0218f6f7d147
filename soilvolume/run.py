"""Orchestration of the method, step by step, with timings, progress and all-or-nothing outputs."""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from scipy import ndimage

from . import grid as gridmod
from . import holes, planes
from .api import Hooks, Result
from .confine import writers_into
from .crop import footprint, polygon_area
from .io import write_las_chunked
from .options import Options
from .outputs import RUN_OUTPUTS, OutputDir, check_output_file, os_errors, output_dir
from .prepare import Prepared, prepare
from .register import register, rotation_deg, shift_at, tilt_deg, transform_points
from .report import absolute_transform, stage_dict, write_json
from .types import GridSpec, SoilVolumeError
from .validate import check_grid_cells
from .volume import budget, difference

REGISTERING = "registering the after cloud onto the before cloud (coarse, then fine)"


class Timer:
    """Per-stage wall times (seconds), in the order they ran."""

    def __init__(self) -> None:
        self.s: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.s[name] = self.s.get(name, 0.0) + time.perf_counter() - t0


def _threads(options: Options) -> None:
    if options.threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(options.threads))


def shared_grid(prep: Prepared, after_thin: np.ndarray, options: Options) -> GridSpec:
    """The grid over the registered after footprint, cell size from the before density."""
    poly = footprint(after_thin[:, :2])
    cell = options.cell
    if cell is None or cell <= 0:
        cell = gridmod.cell_for(prep.before.xyz, poly)
    lo = np.maximum(after_thin.min(axis=0), prep.before_thin.min(axis=0))
    hi = np.minimum(after_thin.max(axis=0), prep.before_thin.max(axis=0))
    if (hi[:2] <= lo[:2]).any():
        raise SoilVolumeError("the registered after cloud does not overlap the before cloud")
    grid = gridmod.make_grid(lo, hi, cell, prep.origin, prep.frame.wkt, prep.frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    return grid


def run_estimate(
    before: Path, after: Path, out_dir: Path, options: Options, *, overwrite: bool, hooks: Hooks,
    before_pipeline=None, after_pipeline=None,
) -> Result:
    """See :func:`soilvolume.api.estimate`."""
    _threads(options)
    timer = Timer()
    inputs = [before, after, before_pipeline, after_pipeline, options.zones, options.stable_mask]
    with output_dir(out_dir, inputs, overwrite) as out, os_errors(out.final), \
            writers_into(out.stage, inputs, RUN_OUTPUTS):
        result = _estimate(before, after, out, options, timer, hooks, before_pipeline, after_pipeline)
    result.outputs = {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p
                      for n, p in out.moved.items()}
    hooks.step(100, "done")
    return result


def _estimate(before, after, out: OutputDir, options: Options, timer: Timer, hooks: Hooks,
              before_pipeline, after_pipeline) -> Result:
    from .tiled import schedule_for

    schedule = schedule_for(before, after, options, before_pipeline or after_pipeline)
    if schedule.kind != "none":
        from .tiled import estimate_tiled

        return estimate_tiled(before, after, out, options, timer, hooks, schedule)
    hooks.step(2, f"reading {before.name} and {after.name} (cropping and thinning on the way)")
    with timer("crop"):
        prep = _prepare(before, after, options, hooks, before_pipeline, after_pipeline)
    timer.s["read"] = prep.read_s  # the rest of streaming: frame, crop, thinning
    timer.s["crop"] -= prep.read_s
    hooks.info(f"kept {len(prep.before):,} before points within {options.radius:g} m of the after "
               f"footprint and {len(prep.after):,} after points; registration subsets "
               f"{len(prep.before_thin):,} + {len(prep.after_thin):,} ({prep.voxel:.2f} m columns)")
    from .georef import resolve

    mode, why = resolve(options.georeferencing, prep.inputs, prep.after_thin, prep.before_thin)
    hooks.info(f"georeferencing: {mode} ({why})")
    if mode == "precise":
        options = options.with_(correction="none")
    hooks.step(15, REGISTERING)
    with timer("register"):
        reg = register(prep.after_thin, prep.before_thin, options, check=hooks.ticker(15, 55, REGISTERING),
                       dense=(prep.after.xyz, prep.before.xyz), precise=mode == "precise")
    reg.georeferencing = {"requested": options.georeferencing, "used": mode, "reason": why}
    timer.s["coarse"], timer.s["fine"] = reg.coarse.seconds, reg.fine.seconds
    timer.s["register_other"] = max(0.0, timer.s.pop("register") - reg.coarse.seconds - reg.fine.seconds)
    hooks.info(f"coarse: {reg.coarse.note}")
    hooks.info(f"fine ({reg.fine.method}): fitness {reg.fine.fitness:.3f}, RMSE {reg.fine.rmse:.3f} m, {reg.fine.note}")
    hooks.step(55, "gridding the average heights")
    with ThreadPoolExecutor(2) as pool:  # numpy sorts and LAZ compression release the GIL
        cloud_job = _write_registered(pool, out, prep, reg, options)
        with timer("grids"):
            after_xyz = transform_points32(prep.after.xyz, reg.transform)
            after_thin = transform_points(prep.after_thin, reg.transform)
            grid = shared_grid(prep, after_thin, options)
            before_job = pool.submit(gridmod.average_height, prep.before.xyz, grid, options.statistic,
                                     spread=True)
            h_a, n_a, s_a = gridmod.average_height(after_xyz, grid, options.statistic, spread=True)
            del after_xyz
            h_b, n_b, s_b = before_job.result()
        hooks.step(70, "estimating the vertical bias correction")
        with timer("planes"):
            sel_b = _points_on(prep.before_thin, grid, np.isfinite(h_b))
            p_b = planes.ransac_plane(sel_b, options.plane_threshold, seed=options.seed)
            p_a = planes.ransac_plane(after_thin, options.plane_threshold, seed=options.seed + 1)
            d_i = planes.plane_offset(p_b, p_a, grid)
        hooks.step(75, "computing the difference and volumes")
        with timer("volume"):
            alt = reg.fine.alternative
            moved = None if alt is None else alt @ np.linalg.inv(reg.transform)
            vols = _volumes(h_a, h_b, n_a, n_b, d_i, grid, options, spread=(s_a, s_b), moved=moved)
            vols["dem_after"] = h_a + prep.origin[2]
        hooks.step(85, "writing outputs")
        with timer("write"):
            _write_rasters(out, h_b, h_a, vols, grid, prep, options)
            if cloud_job is not None:
                cloud_job.result()
    with timer("report"):
        report = _report(prep, reg, grid, vols, p_b, p_a, options, timer)
        from .quality import assess

        prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
        report["quality"] = assess(report, vols["stable"], vols["change_mask"], vols["offset"], grid.cell_area, prior,
                                   vols["diff"])
        for line in report["quality"]["messages"]:
            hooks.info(f"quality ({report['quality']['verdict']}): {line}")
        write_json(out.path("report.json"), report)
        _html(out, report, vols, grid)
    return Result(report)


def _prepare(before, after, options: Options, hooks: Hooks, before_pipeline, after_pipeline) -> Prepared:
    from .stream import open_source

    src_b, src_a = open_source(before, before_pipeline), open_source(after, after_pipeline)
    return prepare(src_b, src_a, options, check=hooks.ticker(2, 15, "reading"))


def _write_registered(pool: ThreadPoolExecutor, out: OutputDir, prep: Prepared, reg, options: Options):
    """Start writing after_registered.laz (every after point, all classes, moved by the
    registration) in the background (None when not asked for)."""
    if not options.keep_registered_cloud:
        return None
    return pool.submit(write_las_chunked, out.path("after_registered.laz"), prep.after_chunks(), prep.origin,
                       prep.frame.wkt, reg.transform)


def transform_points32(xyz: np.ndarray, t: np.ndarray, chunk: int = 4_000_000) -> np.ndarray:
    """A rigid transform of float32 local points, in chunks (no float64 copy of the cloud)."""
    out = np.empty_like(xyz, dtype=np.float32)
    r, s = t[:3, :3].T.astype(np.float32), t[:3, 3].astype(np.float32)
    for i in range(0, len(xyz), chunk):
        out[i : i + chunk] = xyz[i : i + chunk] @ r + s
    return out


def _write_rasters(out: OutputDir, h_b, h_a, vols: dict, grid: GridSpec, prep: Prepared, options: Options) -> None:
    z0 = float(prep.origin[2])  # local -> absolute heights
    gridmod.write_geotiff(out.path("dem_before.tif"), h_b + z0, grid, "average height, before (m)")
    gridmod.write_geotiff(out.path("dem_after.tif"), h_a + z0, grid, "average height, after (m)")
    gridmod.write_geotiff(out.path("difference.tif"), vols["diff"], grid,
                          f"H_after - H_before - correction ({options.correction}) (m)")
    gridmod.write_geotiff(out.path("plane_offset.tif"), vols["offset"], grid,
                          f"vertical correction d_i subtracted ({options.correction}) (m)")
    gridmod.write_geotiff(out.path("filled_mask.tif"), vols["filled_mask"].astype("uint8"), grid,
                          "1 = difference interpolated (sparse cell or filled hole)", "", "uint8")


def _points_on(xyz: np.ndarray, grid: GridSpec, cells: np.ndarray) -> np.ndarray:
    row, col, ok = grid.index(xyz[:, :2])
    keep = np.zeros(len(xyz), bool)
    keep[ok] = cells[row[ok], col[ok]]
    return xyz[keep]


N_COEF = {"surface": 6, "plane": 3, "constant": 1, "none": 0, "paper-plane": 0}


MIN_POINTS = 3  # a robust cell height needs at least this many points


def _volumes(h_a, h_b, n_a, n_b, d_i, grid: GridSpec, options: Options, spread=None, moved=None) -> dict:
    """Raw difference; each epoch's weak cells refilled from its own neighbours; enclosed holes
    of the difference (empty in either epoch) filled from the surrounding difference, which is
    smooth on unchanged ground whatever the terrain -> correction -> change areas, budgets,
    uncertainty, zones. ``spread``: per-cell height spreads (after, before) for per-cell LoDs;
    ``moved``: the rigid move from the accepted pose to a nearly as good one (registration
    uncertainty)."""
    from .change import cell_lod, cell_sigma, change_areas, marginal_volume
    from .uncertainty import detection_level, interp_fraction, thresholded_volumes, volume_uncertainty, z_value

    raw = difference(h_a, h_b)
    max_cells = int(options.fill_holes / grid.cell_area) if options.fill_holes > 0 else None
    weak = dict(ratio=options.min_count_ratio, method=options.fill_method, min_points=MIN_POINTS)
    f_b, m_b = holes.refill_epoch(h_b, n_b, **weak)
    f_a, m_a = holes.refill_epoch(h_a, n_a, **weak)
    filled = difference(f_a, f_b)
    hole = holes.enclosed_holes(np.isfinite(filled), max_cells)
    filled = holes.fill(filled, hole, options.fill_method)
    filled_mask = (m_a | m_b | hole) & np.isfinite(filled)
    offset, params, stable, _ = _correction(filled, d_i, grid, options)
    diff = filled - offset
    area = grid.cell_area
    fill_sigma = _fill_sigma(diff, filled_mask, stable, options)
    lod = detection_level(diff, stable, options.lod_confidence)
    z = z_value(options.lod_confidence)
    if spread is not None:
        se_a = np.where(m_a, np.nan, cell_sigma(spread[0], n_a))
        se_b = np.where(m_b, np.nan, cell_sigma(spread[1], n_b))
        lod_cell = cell_lod(lod, se_a, se_b, z)
        lod_cell = np.maximum(lod_cell, z * fill_sigma)
    else:
        lod_cell = np.full(diff.shape, lod)
    fill_area, cut_area = change_areas(diff, lod_cell, refilled=filled_mask)
    change = fill_area | cut_area
    # stable ground for the error model: never a cell of (or next to) a detected change area,
    # unless the user drew it
    quiet = stable & ~ndimage.binary_dilation(change, iterations=max(1, round(2.0 / grid.cell)))
    if not options.stable_mask and quiet.sum() >= 12:
        stable = quiet
    shift = _pose_effect(f_a, grid, moved)
    reg_v = _signed_budget(shift, fill_area, cut_area, area)
    marginal = {"fill": marginal_volume(diff, fill_area, lod_cell, area),
                "cut": marginal_volume(diff, cut_area, lod_cell, area)}
    marginal["net"] = float(np.hypot(marginal["fill"], marginal["cut"]))
    extra = {k: float(np.hypot(reg_v[k], marginal[k])) for k in ("net", "cut", "fill")}
    unc = volume_uncertainty(diff, stable, change, grid, options.lod_confidence,
                             n_coef=N_COEF[options.correction], filled_mask=filled_mask, fill_sigma=fill_sigma,
                             interp_fraction=interp_fraction(holes.typical_radius(filled_mask)),
                             extra_sigma=extra)
    headline = _signed_budget(diff, fill_area, cut_area, area)
    vols = {
        "raw": raw, "filled": filled, "filled_mask": filled_mask, "offset": offset, "diff": diff,
        "stable": stable, "params": params,
        "uncertainty": {**unc, "lod_m": lod, "registration_m3": reg_v, "marginal_detections_m3": marginal},
        "change_mask": change,
        "compensated": headline, "all_cells": budget(diff, area), "uncompensated": budget(filled, area),
        "paper_plane": budget(filled - d_i, area),
        "change_areas": headline,
        "thresholded": thresholded_volumes(diff, lod, area),
        "holes": holes.summary(diff, filled_mask, area),
        "empty_cells": int((~np.isfinite(raw)).sum()),
        "empty_before": int((n_b == 0).sum()), "empty_after": int((n_a == 0).sum()),
    }
    if options.zones:
        from .zones import zone_budgets

        compared = np.where(np.isfinite(diff), 0.0, np.nan)
        vols["zones"] = zone_budgets(np.where(change, diff, compared), grid, options.zones)
    return vols


def _pose_effect(h_after: np.ndarray, grid: GridSpec, moved: np.ndarray | None) -> np.ndarray:
    """Change of the difference (m per cell) if the after surface moved horizontally by ``moved``
    (4x4, local): -grad(H) . u; its vertical part and tilt are absorbed by the bias correction."""
    if moved is None:
        return np.zeros(h_after.shape)
    x, y = grid.centers_local()
    p = np.stack([x, y, np.nan_to_num(h_after)], axis=-1)
    u = p @ moved[:3, :3].T + moved[:3, 3] - p
    gy, gx = np.gradient(h_after, grid.cell)  # rows run south: d/dy = -d/drow
    return -(gx * u[..., 0] - gy * u[..., 1])


def _signed_budget(diff: np.ndarray, fill_area: np.ndarray, cut_area: np.ndarray, cell_area: float) -> dict:
    """Fill over the fill areas, cut over the cut areas (m3), net = fill - cut."""
    fill = float(np.nansum(np.where(fill_area, diff, 0.0)) * cell_area)
    cut = float(-np.nansum(np.where(cut_area, diff, 0.0)) * cell_area)
    cells = int((fill_area | cut_area).sum())
    return {"net": fill - cut, "cut": cut, "fill": fill, "cells": cells, "area_m2": cells * cell_area}


def _fill_sigma(diff, filled_mask, stable, options: Options) -> np.ndarray:
    """Per-cell one-sigma error (m) of refilled cells, measured by refilling known stable cells
    of the difference with holes of the typical size, or smaller ones where the stable ground
    has no room for them (0 where nothing was refilled)."""
    if not filled_mask.any():
        return np.zeros(diff.shape)
    radius, s = holes.typical_radius(filled_mask), float("nan")
    while not np.isfinite(s) and radius >= 1.0:  # smaller test holes where stable ground is patchy
        s = holes.fill_error(diff, stable, options.fill_method, radius, seed=options.seed)
        radius /= 2.0
    if not np.isfinite(s):  # no room to measure it: one stable-ground noise level per cell
        from .robust import nmad

        s = nmad(diff[stable])
    return np.where(filled_mask, s if np.isfinite(s) else 0.0, 0.0)


def _correction(diff, d_i, grid: GridSpec, options: Options):
    """(correction surface to subtract, its parameters, stable-cell mask, change mask).

    Stable ground is found the same way for every method, so residual statistics and the
    uncertainty are comparable; ``paper-plane`` subtracts the paper's ``d_i`` first."""
    from .correction import apply as apply_correction

    method = options.correction
    base = d_i if method == "paper-plane" else 0.0
    user_mask = None
    if options.stable_mask:
        from .zones import polygons_mask

        user_mask = polygons_mask(options.stable_mask, grid)
    res = apply_correction(diff - base, "none" if method == "paper-plane" else method, grid,
                           user_mask=user_mask)
    offset = np.where(np.isfinite(diff), base + res.surface, np.nan)
    return offset, {**res.params, "method": method}, res.stable_mask, res.change_mask


def _report(prep: Prepared, reg, grid: GridSpec, vols: dict, p_b, p_a, options: Options, timer: Timer) -> dict:
    from dataclasses import asdict

    t_abs = absolute_transform(reg.transform, prep.origin)
    return {
        "software": {"name": "soilvolume", "version": __import__("soilvolume").__version__},
        "volume_m3": vols["compensated"],
        "volume_method": ("fill and cut summed over the areas of significant change: cells whose corrected "
                          "difference exceeds their level of detection, in patches of at least 3 cells, grown into "
                          "connected cells of the same sign above half of it; survey noise elsewhere is not counted"),
        "volume_all_cells_m3": vols["all_cells"],
        "volume_uncompensated_m3": vols["uncompensated"],
        "volume_paper_plane_m3": vols["paper_plane"],
        "volume_change_areas_m3": vols["change_areas"],
        "volume_thresholded_m3": vols["thresholded"],
        "uncertainty_m3": {"net": vols["uncertainty"]["net"],
                           "cut": vols["uncertainty"]["cut"], "fill": vols["uncertainty"]["fill"],
                           "net_change_areas": vols["uncertainty"]["net"],
                           "net_all_cells": vols["uncertainty"]["net_compared_area"],
                           "lod_m": vols["uncertainty"]["lod_m"],
                           "confidence": vols["uncertainty"]["confidence"]},
        "uncertainty": vols["uncertainty"],
        "zones": vols.get("zones", []),
        "correction": {"method": options.correction, "params": vols["params"]},
        "registration": {
            "transform": t_abs, "transform_local": reg.transform, "local_origin": prep.origin,
            "coarse": stage_dict(reg.coarse), "fine": stage_dict(reg.fine),
            "georeferencing": reg.georeferencing,
            "rotation_deg": rotation_deg(reg.transform), "tilt_deg": tilt_deg(reg.transform),
            "shift_m": shift_at(reg.transform, prep.after_thin.mean(axis=0)),
        },
        "planes": {"before": p_b.as_dict(prep.origin), "after": p_a.as_dict(prep.origin)},
        "grid": {
            "cell_m": grid.cell, "rows": grid.rows, "cols": grid.cols, "crs": prep.frame.crs.name,
            "crs_wkt": prep.frame.wkt, "transform": list(grid.transform)[:6],
            "compared_area_m2": vols["all_cells"]["area_m2"], "compared_cells": vols["all_cells"]["cells"],
            "change_area_m2": vols["compensated"]["area_m2"],
            "empty_cells": vols["empty_cells"], "empty_before": vols["empty_before"],
            "empty_after": vols["empty_after"], "statistic": options.statistic,
        },
        "holes": vols["holes"],
        "inputs": prep.inputs,
        "options": asdict(options),
        "timings_s": dict(timer.s),
    }


def _html(out: OutputDir, report: dict, vols: dict, grid: GridSpec) -> None:
    try:
        from .report_html import write_html
    except ImportError:
        return
    arrays = {"difference": vols["diff"], "residual": np.where(vols["stable"], vols["diff"], np.nan),
              "filled_mask": vols["filled_mask"], "dem_after": vols["dem_after"]}
    write_html(report, arrays, grid, out.path("report.html"))


def run_cloud_to_dem(cloud: Path, out_tif: Path, options: Options, *, crs, bounds, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.cloud_to_dem`."""
    from .prepare import prepare_single
    from .stream import open_source

    out_tif = check_output_file(out_tif, [cloud])
    hooks.step(5, f"reading {cloud.name}")
    one = prepare_single(open_source(cloud), crs, options, check=hooks.ticker(5, 40, "reading"))
    xyz, origin, frame = one.xyz, one.origin, one.frame
    if bounds is not None:
        u = frame.xy_unit
        lo = np.array([bounds[0] * u, bounds[1] * u, 0]) - origin
        hi = np.array([bounds[2] * u, bounds[3] * u, 0]) - origin
    else:
        lo, hi = xyz.min(axis=0).astype(float), xyz.max(axis=0).astype(float)
    cell = options.cell or gridmod.choose_cell(len(xyz), polygon_area(footprint(one.thin[:, :2])))
    grid = gridmod.make_grid(lo, hi, cell, origin, frame.wkt, frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    hooks.step(40, f"gridding {len(xyz):,} points on {grid.rows} x {grid.cols} cells of {cell} m")
    h, n = gridmod.average_height(xyz, grid, options.statistic)
    if not np.isfinite(h).any():
        raise SoilVolumeError(f"{cloud}: no points inside the grid (check --bounds)")
    hooks.step(90, f"writing {out_tif.name}")
    with os_errors(out_tif):
        gridmod.write_geotiff(out_tif, h + origin[2], grid, f"average height ({options.statistic}) (m)")
    hooks.step(100, "done")
    return {"cell_m": cell, "rows": grid.rows, "cols": grid.cols, "crs": frame.crs.name,
            "transform": list(grid.transform)[:6], "points": int(len(xyz)),
            "valid_cells": int(np.isfinite(h).sum()), "selection": one.note}


def run_register(before: Path, after: Path, out_cloud: Path, options: Options, *, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.register`."""
    out_cloud = check_output_file(out_cloud, [before, after])
    if out_cloud.suffix.lower() not in (".las", ".laz"):
        raise SoilVolumeError(f"{out_cloud}: the registered cloud is written as .las or .laz")
    hooks.step(5, "reading")
    prep = _prepare(before, after, options, hooks, None, None)
    hooks.step(20, "registering")
    reg = register(prep.after_thin, prep.before_thin, options, check=hooks.ticker(20, 90, "registering"),
                   dense=(prep.after.xyz, prep.before.xyz))
    hooks.step(90, "writing the registered cloud")
    with os_errors(out_cloud):
        write_las_chunked(out_cloud, prep.after_chunks(), prep.origin, prep.frame.wkt, reg.transform)
    hooks.step(100, "done")
    from .report import _clean

    return _clean({"transform": absolute_transform(reg.transform, prep.origin),
                   "coarse": stage_dict(reg.coarse), "fine": stage_dict(reg.fine)})
