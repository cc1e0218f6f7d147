"""A self-contained report.html (the figures come from :mod:`soilvolume.report_figures`): the
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

from .report_figures import (
    PUOR,
    RDBU,
    block_mean,
    colour_ramp,
    difference_map,
    hillshade,
    histogram,
    png_bytes,
    residual_map,
)
from .types import GridSpec

__all__ = ["PUOR", "RDBU", "block_mean", "colour_ramp", "difference_map", "hillshade", "png_bytes",
           "render_html", "write_html"]

_CSS = """body{font-family:sans-serif;margin:1.5em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.2em}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}img{max-width:100%;display:block}
h2{border-bottom:1px solid #ccc;margin-top:1.5em}.note{color:#666;font-size:90%}
figure{margin:.5em 0 1.2em}figcaption{color:#666;font-size:90%;margin-top:.3em;max-width:760px}
.map{position:relative;max-width:100%;outline:1px solid #999;
background:repeating-linear-gradient(45deg,#fff 0 4px,#ddd 4px 6px)}
.map img{width:100%;height:auto}.map svg{position:absolute;left:0;top:0;width:100%;height:100%}
svg.plot{display:block;max-width:100%;height:auto;font-family:sans-serif}"""

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
    th = "".join(f"<th{' class=l' if i == 0 and first_left else ''}>{html.escape(h)}</th>"
                 for i, h in enumerate(header))
    body = "".join(
        "<tr>" + "".join(f"<td{' class=l' if i == 0 and first_left else ''}>{c}</td>"
                         for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _no_data(title: str) -> str:
    return f"<p class=note>{html.escape(title)}: no data</p>"


def _volume_rows(report: dict) -> list[list[str]]:
    unc = _get(report, "uncertainty_m3", default={}) or {}
    rows = []
    for label, key in (("compensated", "volume_m3"), ("uncompensated", "volume_uncompensated_m3"),
                       ("paper plane (d_i)", "volume_paper_plane_m3"),
                       ("thresholded (|d| ≥ LoD)", "volume_thresholded_m3")):
        v = _get(report, key)
        if not isinstance(v, dict):
            continue
        cells = [html.escape(label)]
        for k in ("net", "cut", "fill"):
            s = _fmt(v.get(k))
            if key == "volume_m3" and isinstance(unc.get(k), (int, float)):
                s += f" ± {_fmt(unc.get(k))}"
            cells.append(s)
        cells.append(_fmt(v.get("area_m2"), 1))
        rows.append(cells)
    return rows


def _registration(report: dict) -> str:
    reg = _get(report, "registration", default={}) or {}
    rows = []
    for stage in ("coarse", "fine"):
        s = reg.get(stage)
        if isinstance(s, dict):
            rows.append([stage, _fmt(s.get("method")), _fmt(s.get("fitness"), 4),
                         _fmt(s.get("rmse"), 4), _fmt(s.get("accepted")),
                         _fmt(s.get("seconds"), 2)])
    out = _table(["stage", "method", "fitness", "RMSE (m)", "accepted", "time (s)"], rows)
    t = reg.get("transform")
    if t is not None:
        m = np.asarray(t, float).reshape(4, 4)
        out += "<p>Transform (after → before, row-major):</p>" + _table(
            ["", "c1", "c2", "c3", "c4"],
            [[f"r{i + 1}"] + [f"{x:.6f}" for x in m[i]] for i in range(4)])
    return out


def _kv(d: dict | None, digits: int = 4) -> str:
    if not isinstance(d, dict) or not d:
        return "<p class=note>not available</p>"
    rows = [[html.escape(str(k)), _fmt(v, digits) if not isinstance(v, (list, dict))
             else html.escape(str(v))[:300]] for k, v in d.items()]
    return _table(["item", "value"], rows)


def _inputs(report: dict) -> str:
    rows = []
    for which in ("before", "after"):
        i = _get(report, "inputs", which)
        if isinstance(i, dict):
            rows.append([which, _fmt(i.get("path")), _fmt(i.get("points")), _fmt(i.get("crs"))])
    g = _get(report, "grid", default={}) or {}
    out = _table(["epoch", "file", "points", "CRS"], rows)
    out += _table(["cell (m)", "rows", "cols", "CRS", "compared area (m²)"],
                  [[_fmt(g.get("cell_m")), _fmt(g.get("rows")), _fmt(g.get("cols")),
                    _fmt(g.get("crs")), _fmt(g.get("compared_area_m2"), 1)]], first_left=False)
    return out


def _correction(report: dict) -> str:
    c = _get(report, "correction", default={}) or {}
    params = c.get("params") if isinstance(c.get("params"), dict) else {}
    resid = c.get("residuals") or params.get("residuals")
    out = f"<p>Method: <b>{_fmt(c.get('method') or params.get('method'))}</b></p>"
    if params.get("coefficients") is not None:
        terms = params.get("terms") or [f"c{i}" for i in range(len(params["coefficients"]))]
        out += _table(["term", "coefficient"], [[html.escape(str(t)), f"{v:.6g}"] for t, v in
                                                zip(terms, params["coefficients"], strict=False)])
    return out + "<p>Residuals on stable ground (m):</p>" + _kv(resid)


def _sections(report: dict, arrays: dict, grid: GridSpec) -> list[str]:
    diff = arrays.get("difference")
    lod = (_get(report, "uncertainty", "lod_m") or _get(report, "uncertainty_m3", "lod_m")
           or _get(report, "lod_m"))
    conf = _get(report, "uncertainty", "confidence") or _get(report, "uncertainty_m3", "confidence")
    relief = arrays.get("dem_after")
    figures = [
        ("Difference map", difference_map(diff, grid, relief, arrays.get("filled_mask"))),
        ("Histogram", histogram(diff, lod, conf)),
        ("Stable-ground residuals", residual_map(arrays.get("residual"), grid, relief)),
    ]
    out = ["<h2>Volumes (m³)</h2>" + _table(["", "net", "cut", "fill", "area (m²)"],
                                            _volume_rows(report))
           + "<p class=note>± = 95 % interval including spatially correlated error; cut and "
           "fill are positive, net = fill − cut.</p>"]
    out += [f"<h2>{t}</h2>{fig or _no_data(t)}" for t, fig in figures]
    out.append("<h2>Uncertainty</h2>" + _kv(_uncertainty_summary(report)))
    out.append("<h2>Bias correction</h2>" + _correction(report))
    out.append("<h2>Registration</h2>" + _registration(report))
    out.append("<h2>Inputs and grid</h2>" + _inputs(report))
    if isinstance(report.get("holes"), dict):
        out.append("<h2>Holes and refilled cells</h2>" + _kv(report["holes"], 2))
    out.append("<h2>Timings (s)</h2>" + _kv(report.get("timings_s"), 2))
    return out


def _uncertainty_summary(report: dict) -> dict | None:
    u = report.get("uncertainty") or report.get("uncertainty_m3")
    if not isinstance(u, dict):
        return None
    return {k: v for k, v in u.items() if not isinstance(v, (dict, list))}


def render_html(report: dict, arrays: dict, grid: GridSpec) -> str:
    """The report as one HTML string."""
    title = "Soil volume change report"
    sw = _get(report, "software", "version")
    head = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
            f"<style>{_CSS}</style></head><body><h1>{title}</h1>")
    if sw:
        head += f"<p class=note>soilvolume {_fmt(sw)}</p>"
    return head + "\n".join(_sections(report, arrays, grid)) + "</body></html>"


def write_html(report: dict, arrays: dict, grid: GridSpec, path: str | Path) -> Path:
    """Write report.html atomically; returns its path."""
    path = Path(path)
    text = render_html(report, arrays, grid)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
