"""report.json: built from the run's numbers (the single source for CLI, QGIS and HTML)."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.types import GridSpec
from ..core.wording import cli_tree
from ..inputs.io import atomic_path
from ..options import command_fields
from ..registration.rigid import rotation_deg, shift_at, tilt_deg, transform_points
from ..volumes import coverage
from ..volumes.quality import assess, sentence
from ..volumes.quantities import quantities
from .surface import amend, is_surface, surface_quality, words

if TYPE_CHECKING:
    from ..core.record import RunRecord
    from ..inputs.prepare import Prepared
    from ..options import Options
    from ..registration.register import Registration
    from ..volumes.compute import Volumes


def _clean(v: Any) -> Any:
    """``v`` as JSON reads it back: numpy values as Python's, tuples as lists, NaN and infinities None."""
    return json.loads(json.dumps(v, default=lambda x: x.tolist()), parse_constant=lambda _: None)


def absolute_transform(t_local: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The local-frame transform expressed on absolute coordinates: S(o) T S(-o)."""
    s, s_inv = np.eye(4), np.eye(4)
    s[:3, 3], s_inv[:3, 3] = origin, -origin
    return s @ t_local @ s_inv


def stages(reg: Registration) -> dict:
    """Each stage's fit and the georeferencing decision of a registration."""
    out = {}
    for name, q in (("coarse", reg.coarse), ("fine", reg.fine)):
        fit = {k: getattr(q, k) for k in ("method", "fitness", "rmse", "accepted", "seconds", "note")}
        out[name] = {**fit, "poses_beyond_prior": q.beyond_prior, "transform_local": q.transform}
    return {**out, "georeferencing": {} if reg.georeferencing is None else asdict(reg.georeferencing)}


def registration_entry(reg: Registration, origin: np.ndarray, after: np.ndarray, **extra) -> dict:
    """report.json's ``registration``: the transform (absolute, local, then ``extra``), each stage's fit, and
    the motion as rotation and tilt (°) and the shift (m) at the ``after`` points' mean."""
    t = reg.transform
    motion = {"rotation_deg": rotation_deg(t), "tilt_deg": tilt_deg(t), "shift_m": shift_at(t, after.mean(axis=0))}
    return {"transform": absolute_transform(t, origin), "transform_local": t, **extra, **stages(reg), **motion}


def registration_summary(reg: Registration, origin: np.ndarray) -> dict:
    """What ``soilvolume register`` returns: the absolute 4x4, each stage and the georeferencing decision."""
    return _clean({"transform": absolute_transform(reg.transform, origin), **stages(reg)})


def grid_keys(grid: GridSpec, **crs) -> dict:
    """The keys of a ``grid`` in report.json: cell size, rows, columns, ``crs`` and the affine transform."""
    return {"cell_m": grid.cell, "rows": grid.rows, "cols": grid.cols, **crs, "transform": list(grid.transform)[:6]}


def dem_summary(one, grid: GridSpec, heights: np.ndarray) -> dict:
    """What ``soilvolume dem`` returns: the grid written and the points behind it."""
    return {
        **grid_keys(grid, crs=one.frame.crs.name),
        "points": int(len(one.xyz)),
        "valid_cells": int(np.isfinite(heights).sum()),
        "selection": one.note,
    }


def write_json(path: Path, report: dict, timings: dict[str, float]) -> None:
    """report.json, atomically (``timings``: the run's final ``timings_s``, taken last)."""
    report["timings_s"] = timings
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(_clean(cli_tree(report)), indent=2))  # options worded as flags


def summary_lines(report: dict) -> list[str]:
    """A few human lines for the terminal (options worded as flags)."""
    v, u, g = report["volume_m3"], report["volume_uncompensated_m3"], report["grid"]
    fine, q, surface = report["registration"]["fine"], report.get("quality"), is_surface(report)
    reg = fine["method"] if surface else f"{fine['method']} fitness {fine['fitness']:.3f}, RMSE {fine['rmse']:.3f} m"
    _, cut, fill = words(report)
    return cli_tree(  # options worded as flags
        [
            f"compared area {g['compared_area_m2']:.1f} m2 on {g['cell_m']} m cells ({g['rows']} x {g['cols']})",
            f"registration: {reg}",
            f"volume (change areas, {report['correction']['method']} correction): "
            f"net {v['net']:+.2f} m3  {cut} {v['cut']:.2f} m3  {fill} {v['fill']:.2f} m3",
            f"volume (uncompensated): net {u['net']:+.2f} m3  cut {u['cut']:.2f} m3  fill {u['fill']:.2f} m3",
            f"uncertainty (95 %): net ±{report['uncertainty_m3']['net']:.2f} m3, "
            f"level of detection {report['uncertainty_m3']['lod_m']:.3f} m",
            *filter(None, [coverage.line(report)]),
            f"total time {sum(report['timings_s'].values()):.2f} s",
            *(f"not soil: {line}" for line in nonsoil_lines(report)),
            *([f"quality: {q['verdict'].upper()}"] + [f"  - {m}" for m in q["messages"]] if q else []),
        ]
    )


def nonsoil_lines(report: dict) -> list[str]:
    """What was excluded as not soil, or counted and listed, in plain sentences."""
    return sentence(report.get("excluded") or {})


def _coverage(prep: Prepared, reg, grid: GridSpec, vols: Volumes) -> dict:
    """report.json's ``coverage`` (see :mod:`soilvolume.volumes.coverage`)."""
    after = transform_points(prep.after_thin, reg.transform)
    beyond, outside = coverage.outside(after, grid, vols.dem_b, vols.offset)
    return coverage.summary(vols.coverage, grid.cell_area, beyond, vols.uncertainty["lod_m"], outside)


def build_report(record: RunRecord, timings: dict[str, float]) -> dict:
    """report.json of an estimate run, its quality verdict in it (``timings``: seconds per stage so far)."""
    report = _report(record, timings)
    report["quality"] = assess(report, record.quality)
    if is_surface(report):  # the survey's agreement with the reference surface leads the verdict
        report["quality"] = surface_quality(report, record)
    if record.engine is not None:
        report["engine"] = record.engine
    o = record.options
    if (q := quantities(report, o.bulking, o.shrinkage, o.zones)) is not None:
        report["quantities"] = q
    return report


#: options recorded in report.json only when set: each adds its own keys to the report, so a run
#: without them reads as before they existed
WHEN_SET = ("bulking", "shrinkage", "tolerance", "sections", "gpkg")


def recorded_options(options: Options) -> dict:
    """report.json's ``options``: every option an estimate takes (not another command's, such as
    the stockpile's base), those of :data:`WHEN_SET` only when given."""
    taken = {f.name for f in command_fields("estimate")}
    return {k: v for k, v in asdict(options).items() if k in taken and not (k in WHEN_SET and v in (None, False))}


VOLUME_METHOD = (  # report.json's volume_method
    "fill and cut summed over the areas of significant change: cells whose corrected "
    "difference exceeds their level of detection, in patches of at least 3 cells, grown into "
    "connected cells of the same sign above half of it; survey noise elsewhere is not counted. "
    "A cell's height in each epoch is the robust mean of its points, moved to the cell's centre "
    "along the local slope where its points cover it unevenly; cells with too few points and "
    "enclosed holes are interpolated from the surrounding difference (filled_mask.tif). Only soil "
    "counts: points the epochs' rules say are not soil are not gridded, objects that moved between the "
    "surveys are left out, objects in one survey only of a machine's size are left out (or counted with "
    "objects=count) and listed (excluded, excluded.tif); holes without any point inside the works (water, "
    "shadow) widen the interval by what they may hide (blind)"
)


def _uncertainty_m3(vols: Volumes) -> dict:
    """report.json's ``uncertainty_m3``: the headline's ± and those of the other sums."""
    u = vols.uncertainty
    keys = {"net": "net", "cut": "cut", "fill": "fill", "net_change_areas": "net", "net_all_cells": "net_compared_area"}
    return {**{k: u[v] for k, v in keys.items()}, "lod_m": u["lod_m"], "confidence": u["confidence"]}


def _grid(prep: Prepared, grid: GridSpec, vols: Volumes, options: Options) -> dict:
    """report.json's ``grid``: the rasters' grid, CRS, compared area and empty cells."""
    return {
        **grid_keys(grid, crs=prep.frame.crs.name, crs_wkt=prep.frame.wkt),
        "compared_area_m2": vols.all_cells["area_m2"],
        "compared_cells": vols.all_cells["cells"],
        "change_area_m2": vols.compensated["area_m2"],
        "empty_cells": vols.empty_cells,
        "empty_before": vols.empty_before,
        "empty_after": vols.empty_after,
        "statistic": options.statistic,
    }


def _report(record: RunRecord, timings: dict[str, float]) -> dict:
    prep, reg, grid, vols, options = record.prep, record.reg, record.grid, record.vols, record.options
    p_b, p_a = record.planes
    report = {
        "software": {"name": "soilvolume", "version": __import__("soilvolume").__version__},
        "volume_m3": vols.compensated,
        "volume_method": VOLUME_METHOD,
        "volume_all_cells_m3": vols.all_cells,
        "volume_uncompensated_m3": vols.uncompensated,
        "volume_paper_plane_m3": vols.paper_plane,
        "volume_change_areas_m3": vols.change_areas,
        "volume_thresholded_m3": vols.thresholded,
        "uncertainty_m3": _uncertainty_m3(vols),
        "uncertainty": vols.uncertainty,
        "excluded": {
            **vols.excluded,
            "rule": {e: prep.inputs[e].get("soil_rule", "") for e in ("before", "after")},
            "by_classification": all(r is not None and r.use_class for r in prep.rules),
        },
        "blind": vols.blind,
        "zones": vols.zones,
        "correction": {"method": options.correction, "params": vols.params},
        "registration": registration_entry(reg, prep.origin, prep.after_thin, local_origin=prep.origin),
        "planes": {"before": p_b.as_dict(prep.origin), "after": p_a.as_dict(prep.origin)},
        "grid": _grid(prep, grid, vols, options),
        "holes": vols.holes,
        "coverage": _coverage(prep, reg, grid, vols),
        "inputs": prep.inputs,
        "options": recorded_options(options),
        "timings_s": timings,
    }
    return amend(with_unseen(with_nothing_found(report)), prep, vols)  # against a surface: its reference


def with_nothing_found(report: dict) -> dict:
    """``report`` with the net's, cut's and fill's 95 % half-widths at least the compared area's when no change
    area was found: "no change" speaks for every compared cell, and a change under the detection level (a small
    pit, a compaction) is not measured by an empty change area's interval of +-0."""
    if report["grid"]["change_area_m2"] > 0:
        return report
    u = report["uncertainty_m3"]
    u.update({k: max(u[k], u["net_all_cells"]) for k in ("net", "cut", "fill", "net_change_areas")})
    return report


def with_unseen(report: dict) -> dict:
    """``report`` with the net's, cut's and fill's 95 % half-widths widened by what the part of the after
    footprint no before data covers could hide (``coverage.unseen_volume_bound_m3``) once that part is named in
    the verdict (:data:`~soilvolume.volumes.coverage.CAUTION_SHARE`): the volumes are the compared area's; the
    interval is for the site the after survey shows."""
    cov = report.get("coverage") or {}
    bound = float(cov.get("unseen_volume_bound_m3", 0.0))
    if bound > 0 and 1.0 - cov.get("compared_share", 1.0) > coverage.CAUTION_SHARE:
        u = report["uncertainty_m3"]
        u.update({k: u[k] + bound for k in ("net", "cut", "fill", "net_change_areas")}, unseen_m3=bound)
    return report
