"""The outputs of a series run: report.json (``epochs``, ``periods``, ``cumulative``), the ledger
CSV, each epoch's DEM and each period's (and the cumulative's) difference as GeoTIFFs, and
report.html (:mod:`.serieshtml`)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from ..core.wording import cli_tree
from ..dem.geotiff import write_grid
from ..inputs.io import atomic_path
from ..options import Options
from ..volumes.quality import epoch_checks, period_quality
from ..volumes.quantities import scaled
from .report import grid_keys, recorded_options, registration_entry, write_json
from .seriesgrade import LEDGER_GRADE, ledger_figures, with_grade, write_grades
from .serieshtml import changes, write_series_html

LEDGER = "ledger.csv"
_FIGURES = tuple(f"{k}{pm}_m3" for k in ("net", "cut", "fill") for pm in ("", "_pm"))  # net_m3, net_pm_m3, ...
LEDGER_COLUMNS = ("period", "from", "to", "from_date", "to_date", *_FIGURES)


def dem_name(k: int) -> str:
    return f"dem_epoch{k}.tif"


def difference_name(i: int, j: int, cumulative: bool = False) -> str:
    return f"{'cumulative' if cumulative else 'difference'}_{i}_{j}.tif"


def _registration(fit, origin: np.ndarray) -> dict:
    if fit is None:  # E0: the frame itself
        return {"transform": np.eye(4), "reference": True}
    return registration_entry(fit.reg, origin, fit.prep.after_thin)


def _change(c, dates: list, cell_area: float, quality: dict, cumulative: bool = False) -> dict:
    u = c.uncertainty
    return {
        "from": c.start,
        "to": c.end,
        "dates": [dates[c.start], dates[c.end]],
        "volume_m3": c.volume,
        "uncertainty_m3": {"net": u["net"], "cut": u["cut"], "fill": u["fill"]},
        "uncertainty": u,
        "change_area_m2": float((c.fill_area | c.cut_area).sum()) * cell_area,
        "difference": difference_name(c.start, c.end, cumulative),
        "quality": quality,
    }


SERIES_METHOD = (  # report.json's method of a series run
    "every later epoch registered into E0's frame and corrected once relative to E0 on stable "
    "ground; all epochs on one grid and one set of cells; a period's net is summed over the "
    "works (every period's areas of significant change), so the periods add up to the "
    "cumulative net; cut and fill over each period's own areas of significant change; "
    "below_detection = net - (fill - cut)"
)


def _epoch(k: int, run, fits, vols, origin: np.ndarray) -> dict:
    """report.json's entry of epoch ``k``: its file, date and where the date came from, points,
    registration into E0 and correction."""
    fit = fits[k - 1] if k else None
    cloud = fits[0].prep.before if fit is None else fit.prep.after
    info = fits[0].prep.inputs["before"] if fit is None else fit.prep.inputs["after"]
    return {
        "index": k,
        "path": str(run.path),
        "date": run.date,
        "date_source": run.date_source,  # "LAS header", "given" (--dates) or None
        "points": info.get("points", len(cloud)),
        "input": info,
        "registration": _registration(fit, origin),
        "correction": None if k == 0 else {"method": fit.options.correction, "params": vols[k - 1].params},
        "dem": dem_name(k),
    }


def _series_grid(grid: GridSpec, series, origin: np.ndarray) -> dict:
    """report.json's ``grid`` of a series run: the one grid, its compared, works and refilled areas."""
    area = grid.cell_area
    return {
        **grid_keys(grid, crs_wkt=grid.crs_wkt),
        "compared_area_m2": float(series.valid.sum()) * area,
        "works_area_m2": float(series.works.sum()) * area,
        "refilled_area_m2": float(series.refilled.sum()) * area,
        "stable_cells": int(series.stable.sum()),
        "local_origin": origin,
    }


def build_series_report(runs, fits, vols, series, grid: GridSpec, options: Options, timer) -> dict:
    """report.json of a series run (``runs``: its epochs; ``fits``: the later epochs' registrations;
    ``vols``: the volume steps E0 -> Ek), each period and the cumulative with its quality verdict."""
    origin = np.asarray(fits[0].prep.origin, dtype=np.float64)
    dates = [e.date for e in runs]
    epochs = [_epoch(k, run, fits, vols, origin) for k, run in enumerate(runs)]
    prior = {"shift": options.max_gps_shift, "rotation": options.max_gps_rotation, "tilt": options.max_gps_tilt}
    checks = epoch_checks([e["registration"] for e in epochs], vols, prior)

    def change(c, cumulative: bool = False) -> dict:
        return _change(c, dates, grid.cell_area, period_quality(c, checks, vols, grid.cell_area), cumulative)

    return {
        "software": {"name": "soilvolume", "version": __import__("soilvolume").__version__},
        "command": "series",
        "method": SERIES_METHOD,
        "epochs": epochs,
        "periods": [change(c) for c in series.periods],
        "cumulative": change(series.cumulative, cumulative=True),
        "check": {
            "periods_net_sum_m3": float(sum(c.volume["net"] for c in series.periods)),
            "cumulative_net_m3": series.cumulative.volume["net"],
        },
        "grid": _series_grid(grid, series, origin),
        "options": recorded_options(options),
        "timings_s": dict(timer.s),
    }


def write_ledger(path: Path, report: dict) -> None:
    """One row per period and one for the cumulative: epochs, dates, net/cut/fill and their ±
    (with a design: the grade at its end and the cut and fill to go it did, :data:`LEDGER_GRADE`)."""
    designed = "design" in report
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(LEDGER_COLUMNS + (LEDGER_GRADE if designed else ()))
        for name, p in changes(report):
            v, u = p["volume_m3"], p["uncertainty_m3"]
            dates = [d or "" for d in p["dates"]]
            figures = [f"{x:.3f}" for k in ("net", "cut", "fill") for x in (v[k], u[k])]
            w.writerow([name, p["from"], p["to"], *dates, *figures, *(ledger_figures(p) if designed else ())])


def write_rasters(out, series, base: np.ndarray, grid: GridSpec, graded=None) -> None:
    """Each epoch's corrected DEM (E0's heights ``base`` at the cell centres + D_k, absolute),
    every difference, and with a design each epoch's grade (:func:`.seriesgrade.write_grades`)."""
    if graded is not None:
        write_grades(out, graded, grid)
    z0 = float(grid.origin[2])
    for k, d in enumerate(series.to_e0):
        desc = f"epoch {k} heights in E0's frame, corrected once relative to E0 (m)"
        write_grid(out.path(dem_name(k)), base + d + z0, grid, desc)
    for c in [*series.periods, series.cumulative]:  # the cumulative's start is E0
        name = difference_name(c.start, c.end, c is series.cumulative)
        write_grid(out.path(name), c.diff, grid, f"epoch {c.end} - epoch {c.start} (m)")


def write_reports(out, epochs, fits, vols, series, grid: GridSpec, options: Options, timer, graded=None) -> dict:
    """report.json, the ledger and report.html of a series run into the output folder ``out`` (with each
    period's quantities by ``--bulking``/``--shrinkage``, the progress against a design when ``graded``)."""
    report = build_series_report(epochs, fits, vols, series, grid, options, timer)
    factors = {"bulking": options.bulking, "shrinkage": options.shrinkage}
    if options.bulking is not None or options.shrinkage is not None:  # bank, loose and compacted volumes
        for p in [*report["periods"], report["cumulative"]]:
            p["quantities"] = scaled(p["volume_m3"], p["uncertainty_m3"], factors)
    report = cli_tree(with_grade(report, graded))
    write_ledger(out.path(LEDGER), report)
    write_series_html(out.path("report.html"), report, series, grid, vols[0].dem_b)
    write_json(out.path("report.json"), report, timer.totals())
    return report
