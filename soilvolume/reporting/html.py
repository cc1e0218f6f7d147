"""A self-contained report.html (the figures come from :mod:`soilvolume.reporting.figures`): the
result in plain words (volumes with their uncertainty, significance, quality verdict), run date,
software version, inputs and every parameter, registration as rotation and shift. No network
access, no scripts, tolerant of missing report keys and arrays."""

from __future__ import annotations

import html
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..core import wording
from ..core.types import GridSpec
from .figures import (
    PUOR,
    RDBU,
    block_mean,
    colour_ramp,
    difference_map,
    hillshade,
    png_bytes,
    residual_map,
)
from .histogram import histogram

__all__ = [
    "PUOR",
    "RDBU",
    "block_mean",
    "colour_ramp",
    "difference_map",
    "hillshade",
    "png_bytes",
    "render_html",
    "write_html",
]

_CSS = """body{font-family:sans-serif;margin:1.5em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.2em}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}img{max-width:100%;display:block}
h2{border-bottom:1px solid #ccc;margin-top:1.5em}.note{color:#666;font-size:90%}
figure{margin:.5em 0 1.2em}figcaption{color:#666;font-size:90%;margin-top:.3em;max-width:760px}
.map{position:relative;max-width:100%;outline:1px solid #999;
background:repeating-linear-gradient(45deg,#fff 0 4px,#ddd 4px 6px)}
.map img{width:100%;height:auto}.map svg{position:absolute;left:0;top:0;width:100%;height:100%}
svg.plot{display:block;max-width:100%;height:auto;font-family:sans-serif}
p.big{font-size:120%}.verdict{padding:.3em .6em;display:inline-block;background:#eee}
.verdict.reliable{background:#dfd}.verdict.use-with-caution{background:#ffd}.verdict.not-reliable{background:#fdd}"""


def _get(d: Any, *keys: str, default: Any = None) -> Any:
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}"
    if isinstance(v, (float, np.floating)):
        return "–" if not math.isfinite(float(v)) else f"{float(v):,.{digits}f}"
    return html.escape(str(v))


def _table(header: list[str], rows: list[list[Any]], first_left: bool = True) -> str:
    th = "".join(
        f"<th{' class=l' if i == 0 and first_left else ''}>{html.escape(h)}</th>" for i, h in enumerate(header)
    )
    body = "".join(
        "<tr>"
        + "".join(f"<td{' class=l' if i == 0 and first_left else ''}>{c}</td>" for i, c in enumerate(r))
        + "</tr>"
        for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def _no_data(title: str) -> str:
    return f"<p class=note>{html.escape(title)}: no data</p>"


VOLUME_ROWS = (  # report key, row label, uncertainty_m3 key prefix of its ± (or None)
    ("volume_m3", "areas of significant change (headline)", ""),
    ("volume_all_cells_m3", "every compared cell, as the paper sums (incl. noise)", "all_cells"),
    ("volume_thresholded_m3", "cells beyond the level of detection", None),
    ("volume_uncompensated_m3", "without the vertical correction", None),
    ("volume_paper_plane_m3", "with the paper's plane offset d_i", None),
)
LABELS = {  # report keys -> words (units in brackets)
    "net": "net (m³)",
    "cut": "cut (m³)",
    "fill": "fill (m³)",
    "net_compared_area": "net, all compared cells (m³)",
    "net_all_cells": "net, every compared cell (m³)",
    "net_change_areas": "net, change areas (m³)",
    "interpolation_sigma_m3": "interpolation error, 1σ (m³)",
    "confidence": "confidence level",
    "sigma_m": "noise on stable ground, NMAD (m)",
    "lod_m": "level of detection (m)",
    "nugget_m2": "uncorrelated error variance (m²)",
    "psill_m2": "spatially correlated error variance (m²)",
    "range_m": "correlation range (m)",
    "bias_sigma_m": "error of the correction's level, 1σ (m)",
    "interpolated_m3": "interpolated volume (m³)",
    "refill_sigma_m3": "refill error, 1σ (m³)",
    "stable_cells": "stable-ground cells",
    "change_area_m2": "detected change area (m²)",
    "filled_cells": "refilled cells",
    "filled_area_m2": "refilled area (m²)",
    "filled_net_m3": "net volume in refilled cells (m³)",
    "mean": "mean (m)",
    "std": "standard deviation (m)",
    "nmad": "NMAD (m)",
    "rmse": "RMSE (m)",
    "n_cells": "cells",
    "crop": "reading and cropping",
    "read": "reading",
    "coarse": "coarse registration",
    "fine": "fine registration",
    "register_other": "registration, other",
    "grids": "gridding",
    "planes": "reference planes",
    "volume": "volumes and uncertainty",
    "write": "writing rasters",
    "report": "report",
}
UNIT_WORDS = {"m": "m", "m2": "m²", "m3": "m³", "deg": "°", "s": "s"}


def label(key: str) -> str:
    """Words for a report key: from LABELS, else the key with its unit suffix in brackets."""
    if key in LABELS:
        return LABELS[key]
    head, _, unit = key.rpartition("_")
    if head and unit in UNIT_WORDS:
        return f"{head.replace('_', ' ')} ({UNIT_WORDS[unit]})"
    return key.replace("_", " ")


def _pm(value: Any, half: Any) -> str:
    text = _fmt(value)
    return text + (f" ± {_fmt(half)}" if isinstance(half, (int, float)) else "")


def _volume_rows(report: dict) -> list[list[str]]:
    unc = _get(report, "uncertainty_m3", default={}) or {}
    rows = []
    for key, text, prefix in VOLUME_ROWS:
        v = _get(report, key)
        if not isinstance(v, dict):
            continue
        half = (
            {}
            if prefix is None
            else (
                {k: unc.get(k) for k in ("net", "cut", "fill")} if prefix == "" else {"net": unc.get(f"net_{prefix}")}
            )
        )
        cells = [html.escape(text)] + [_pm(v.get(k), half.get(k)) for k in ("net", "cut", "fill")]
        rows.append(cells + [_fmt(v.get("area_m2"), 1)])
    return rows


def _summary(report: dict, arrays: dict | None = None) -> str:
    """The result in plain words: volumes with their ±, why a cut or fill reads 0 while the map
    shows some, significance, quality verdict."""
    from .headline import zero_notes
    from .summary import quality, significance
    from .surface import words

    v, u = _get(report, "volume_m3", default={}) or {}, _get(report, "uncertainty_m3", default={}) or {}
    conf, (lead, cut, fill) = u.get("confidence", 0.95), words(report)
    out = (
        f"<p class=big>{lead} <b>{_pm(v.get('net'), u.get('net'))} m³</b> "
        f"({cut} {_pm(v.get('cut'), u.get('cut'))} m³, {fill} {_pm(v.get('fill'), u.get('fill'))} m³; "
        f"± at {_fmt(conf * 100, 0)} % confidence) over {_fmt(v.get('area_m2'), 0)} m².</p>"
        + zero_notes(report, arrays, (lead, cut, fill))
        + f"<p>{html.escape(significance(report))}</p>"
    )
    q = quality(report)
    if q["verdict"]:
        verdict = html.escape(q["verdict"])
        out += f"<p class='verdict {verdict.replace(' ', '-')}'>Quality: <b>{verdict}</b></p>"
    if q["messages"]:
        out += "<ul>" + "".join(f"<li>{html.escape(m)}</li>" for m in q["messages"]) + "</ul>"
    return out


def _registration(report: dict) -> str:
    """Each stage's fit, and the transform as a rotation (°) and a shift (m)."""
    from .summary import rotation_shift

    reg = _get(report, "registration", default={}) or {}
    rows = []
    for stage in ("coarse", "fine"):
        s = reg.get(stage)
        if isinstance(s, dict):
            rows.append(
                [
                    stage,
                    _fmt(s.get("method")),
                    _fmt(s.get("fitness"), 3),
                    _fmt(s.get("rmse"), 3),
                    _fmt(s.get("accepted")),
                    _fmt(s.get("note")),
                ]
            )
    out = _table(["stage", "method", "fitness", "RMSE (m)", "kept", "note"], rows)
    local = reg.get("transform_local")
    if local is None:
        return out
    m = rotation_shift(local)
    out += _table(
        ["rotation (°)", "of which tilt (°)", "heading change (°)", "shift (m)", "east (m)", "north (m)", "up (m)"],
        [
            [
                _fmt(m["rotation_deg"], 3),
                _fmt(m["tilt_deg"], 3),
                _fmt(m["yaw_deg"], 3),
                _fmt(m["shift_m"], 3),
                _fmt(m["dx_m"], 3),
                _fmt(m["dy_m"], 3),
                _fmt(m["shift_vertical_m"], 3),
            ]
        ],
        first_left=False,
    )
    return out + (
        "<p class=note>How the after survey was moved onto the before survey (shift at the "
        "centre of the data). The 4×4 matrix is in report.json.</p>"
    )


def _kv(d: dict | None, digits: int = 4) -> str:
    if not isinstance(d, dict) or not d:
        return "<p class=note>not available</p>"
    rows = [
        [html.escape(label(str(k))), _fmt(v, digits) if not isinstance(v, (list, dict)) else html.escape(str(v))[:300]]
        for k, v in d.items()
    ]
    return _table(["", "value"], rows)


def _inputs(report: dict) -> str:
    rows = []
    for which in ("before", "after"):
        i = _get(report, "inputs", which)
        if isinstance(i, dict):
            rows.append(
                [
                    which,
                    _fmt(i.get("path")),
                    _fmt(i.get("points")),
                    _fmt(i.get("points_used")),
                    _fmt(i.get("selection")),
                    _fmt(i.get("crs")),
                ]
            )
    g = _get(report, "grid", default={}) or {}
    out = _table(["survey", "file", "points", "points used", "selection", "CRS"], rows)
    out += _table(
        ["cell (m)", "rows", "columns", "CRS of the rasters", "compared area (m²)"],
        [
            [
                _fmt(g.get("cell_m")),
                _fmt(g.get("rows")),
                _fmt(g.get("cols")),
                _fmt(g.get("crs")),
                _fmt(g.get("compared_area_m2"), 1),
            ]
        ],
        first_left=False,
    )
    return out


def _parameters(report: dict) -> str:
    """Every option of the run with its label, value and whether it is the default."""
    from dataclasses import MISSING, fields

    from ..options import Options

    given = report.get("options")
    if not isinstance(given, dict):
        return "<p class=note>not available</p>"
    rows = []
    for f in fields(Options):
        if f.name not in given:
            continue
        meta, value = f.metadata, given[f.name]
        unit = UNIT_WORDS.get(meta.get("unit") or "", meta.get("unit") or "")
        default = "" if f.default is MISSING else ("default" if value == f.default else f"default {f.default}")
        if value is None:  # optional files are "none"; other unset options are chosen by the engine
            text = "none" if str(meta.get("help", "")).startswith("optional") else "automatic"
        else:
            text = f"{_fmt(value, 3)} {unit}".strip()
        rows.append([html.escape(meta.get("label") or f.name), text, default])
    return _table(["parameter", "value", ""], rows)


def _correction(report: dict) -> str:
    c = _get(report, "correction", default={}) or {}
    params = c.get("params") if isinstance(c.get("params"), dict) else {}
    resid = c.get("residuals") or params.get("residuals")
    out = f"<p>Method: <b>{_fmt(c.get('method') or params.get('method'))}</b></p>"
    if params.get("coefficients") is not None:
        terms = params.get("terms") or [f"c{i}" for i in range(len(params["coefficients"]))]
        out += _table(
            ["term", "coefficient"],
            [[html.escape(str(t)), f"{v:.6g}"] for t, v in zip(terms, params["coefficients"], strict=False)],
        )
    return out + "<p>Residuals on stable ground after the correction:</p>" + _kv(resid)


def _sections(report: dict, arrays: dict, grid: GridSpec) -> list[str]:
    diff = arrays.get("difference")
    lod = _get(report, "uncertainty", "lod_m") or _get(report, "uncertainty_m3", "lod_m") or _get(report, "lod_m")
    conf = _get(report, "uncertainty", "confidence") or _get(report, "uncertainty_m3", "confidence")
    relief = arrays.get("dem_after")
    figures = [
        ("Difference map", difference_map(diff, grid, relief, arrays.get("filled_mask"), change=arrays.get("change"))),
        ("Histogram", histogram(diff, lod, conf)),
        ("Stable-ground residuals", residual_map(arrays.get("residual"), grid, relief)),
    ]
    out = [
        "<h2>Result</h2>" + _summary(report, arrays),
        "<h2>Volumes (m³)</h2>"
        + _table(["", "net", "cut", "fill", "area (m²)"], _volume_rows(report))
        + "<p class=note>± = half-width of the interval at the confidence level, including spatially "
        "correlated error; cut and fill are positive, net = fill − cut.</p>",
    ]
    out += [f"<h2>{t}</h2>{fig or _no_data(t)}" for t, fig in figures]
    from .excluded import classes_map, excluded_section

    nonsoil_map = classes_map(arrays.get("classes"), grid, relief) or ""
    out.append("<h2>What is not soil</h2>" + nonsoil_map + excluded_section(report, _table))
    out.append("<h2>Uncertainty</h2>" + _kv(_uncertainty_summary(report)))
    out.append("<h2>Vertical bias correction</h2>" + _correction(report))
    from .surface import is_surface, section

    out.append("<h2>Reference surface</h2>" + section(report, _table) if is_surface(report) else "")
    out.append("<h2>Registration</h2>" + _registration(report))
    out.append("<h2>Inputs and grid</h2>" + _inputs(report))
    out.append("<h2>Parameters</h2>" + _parameters(report))
    if isinstance(report.get("holes"), dict):
        out.append("<h2>Holes and refilled cells</h2>" + _kv(report["holes"], 2))
    out.append("<h2>Timings (s)</h2>" + _kv(report.get("timings_s"), 2))
    return out


def _uncertainty_summary(report: dict) -> dict | None:
    u = report.get("uncertainty") or report.get("uncertainty_m3")
    if not isinstance(u, dict):
        return None
    return {k: v for k, v in u.items() if not isinstance(v, (dict, list))}


def render_html(report: dict, arrays: dict, grid: GridSpec, run_date: str | None = None) -> str:
    """The report as one HTML string (``run_date``: when the run ended; now when not given)."""
    from datetime import datetime

    title = "Soil volume change report"
    date = run_date or datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    sw = _get(report, "software", "version")
    head = (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
        f"<style>{_CSS}</style></head><body><h1>{title}</h1>"
        f"<p class=note>Run on {html.escape(date)} with soilvolume {_fmt(sw or 'unknown')}.</p>"
    )
    return head + "\n".join(_sections(report, arrays, grid)) + "</body></html>"


def write_html(report: dict, arrays: dict, grid: GridSpec, path: str | Path) -> Path:
    """Write report.html atomically; returns its path."""
    path = Path(path)
    text = wording.html(render_html(report, arrays, grid))  # options as spans naming them
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
