"""report.html of a pair or a survey against a design (``templates/report.html.j2``): the result in
plain words, the figures, inputs, parameters and registration; no network access, no scripts,
tolerant of missing report keys and arrays. When the headline's cut (or fill) reads 0 while the map
shows such cells, a note says which rule of the change areas (:mod:`soilvolume.volumes.change`) left
how many out, and which sum to trust."""

from __future__ import annotations

from dataclasses import MISSING, fields
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from markupsafe import Markup

from ..core import wording
from ..core.types import GridSpec
from ..options import Options
from ..volumes.change import BUFFER_CELLS, MIN_CELLS
from . import earthworks, excluded, page, surface
from .figures import difference_map, residual_map
from .histogram import histogram
from .summary import quality, rotation_shift, significance
from .text import UNIT_WORDS, Table, fmt, get, kv, pm

VOLUME_ROWS = (  # report key, row label, the uncertainty_m3 keys of its net, cut and fill ± ("": none)
    ("volume_m3", "areas of significant change (headline)", ("net", "cut", "fill")),
    ("volume_all_cells_m3", "every compared cell, as the paper sums (incl. noise)", ("net_all_cells", "", "")),
    ("volume_thresholded_m3", "cells beyond the level of detection", ("", "", "")),
    ("volume_uncompensated_m3", "without the vertical correction", ("", "", "")),
    ("volume_paper_plane_m3", "with the paper's plane offset d_i", ("", "", "")),
)


def volume_rows(report: dict) -> list[list[str]]:
    """Each volume sum of the report: net, cut and fill with their ± where it has one, and the area."""
    unc = get(report, "uncertainty_m3", default={}) or {}
    rows = []
    for key, text, halves in VOLUME_ROWS:
        if isinstance(v := get(report, key), dict):
            sums = [pm(v.get(k), unc.get(h)) for k, h in zip(("net", "cut", "fill"), halves, strict=True)]
            rows.append([text, *sums, fmt(v.get("area_m2"), 1)])
    return rows


def result(report: dict, arrays: dict) -> dict:
    """The headline in words: volumes with their ±, notes on a cut or fill reading 0 while the map
    shows some, the significance and the quality verdict with its reasons."""
    v, u = get(report, "volume_m3", default={}) or {}, get(report, "uncertainty_m3", default={}) or {}
    lead, cut, fill = surface.words(report)
    return {
        "lead": lead,
        "net": pm(v.get("net"), u.get("net")),
        "parts": f"{cut} {pm(v.get('cut'), u.get('cut'))} m³, {fill} {pm(v.get('fill'), u.get('fill'))} m³",
        "confidence": fmt(u.get("confidence", 0.95) * 100, 0),
        "area": fmt(v.get("area_m2"), 0),
        "notes": zero_notes(report, arrays, (lead, cut, fill)),
        "significance": significance(report),
        "quality": quality(report),
    }


def registration(report: dict) -> list[Table]:
    """Each stage's fit, and the transform as a rotation (°) and a shift (m)."""
    reg = get(report, "registration", default={}) or {}
    rows = [
        [stage, fmt(s.get("method")), fmt(s.get("fitness"), 3), fmt(s.get("rmse"), 3), fmt(s.get("accepted"))]
        + [fmt(s.get("note"))]
        for stage in ("coarse", "fine")
        if isinstance(s := reg.get(stage), dict)
    ]
    tables = [Table(["stage", "method", "fitness", "RMSE (m)", "kept", "note"], rows)]
    if reg.get("transform_local") is not None:
        m = rotation_shift(reg["transform_local"])
        keys = ("rotation_deg", "tilt_deg", "yaw_deg", "shift_m", "dx_m", "dy_m", "shift_vertical_m")
        head = ["rotation (°)", "of which tilt (°)", "heading change (°)", "shift (m)", "east (m)", "north (m)"]
        tables.append(Table([*head, "up (m)"], [[fmt(m[k], 3) for k in keys]], first_left=False))
    return tables


def inputs(report: dict) -> list[Table]:
    """The surveys read and the grid of the rasters."""
    keys = ("path", "points", "points_used", "selection", "crs")
    surveys = {w: get(report, "inputs", w) for w in ("before", "after")}
    rows = [[w] + [fmt(i.get(k)) for k in keys] for w, i in surveys.items() if isinstance(i, dict)]
    g = get(report, "grid", default={}) or {}
    grid_row = [fmt(g.get(k)) for k in ("cell_m", "rows", "cols", "crs")] + [fmt(g.get("compared_area_m2"), 1)]
    grid_head = ["cell (m)", "rows", "columns", "CRS of the rasters", "compared area (m²)"]
    return [
        Table(["survey", "file", "points", "points used", "selection", "CRS"], rows),
        Table(grid_head, [grid_row], first_left=False),
    ]


def parameters(report: dict) -> Table | None:
    """Every option of the run with its label, value and whether it is the default."""
    given = report.get("options")
    if not isinstance(given, dict):
        return None
    rows = []
    for f in (f for f in fields(Options) if f.name in given):
        meta, value = f.metadata, given[f.name]
        unit = UNIT_WORDS.get(meta.get("unit") or "", meta.get("unit") or "")
        default = "" if f.default is MISSING else ("default" if value == f.default else f"default {f.default}")
        if value is None:  # optional files are "none"; other unset options are chosen by the engine
            text = "none" if str(meta.get("help", "")).startswith("optional") else "automatic"
        else:
            text = f"{fmt(value, 3)} {unit}".strip()
        rows.append([meta.get("label") or f.name, text, default])
    return Table(["parameter", "value", ""], rows)


def correction(report: dict) -> dict:
    """The vertical correction's method, its polynomial's terms and its residuals on stable ground."""
    c = get(report, "correction", default={}) or {}
    params = c.get("params") if isinstance(c.get("params"), dict) else {}
    terms = None
    if params.get("coefficients") is not None:
        names = params.get("terms") or [f"c{i}" for i in range(len(params["coefficients"]))]
        rows = [[str(t), f"{v:.6g}"] for t, v in zip(names, params["coefficients"], strict=False)]
        terms = Table(["term", "coefficient"], rows)
    residuals = kv(c.get("residuals") or params.get("residuals"))
    return {"method": fmt(c.get("method") or params.get("method")), "terms": terms, "residuals": residuals}


def figures(report: dict, arrays: dict, grid: GridSpec) -> list[tuple[str, Markup | None]]:
    """(title, figure or None) of the difference map, the histogram and the residual map."""
    diff, relief = arrays.get("difference"), arrays.get("dem_after")
    lod = get(report, "uncertainty", "lod_m") or get(report, "uncertainty_m3", "lod_m") or get(report, "lod_m")
    conf = get(report, "uncertainty", "confidence") or get(report, "uncertainty_m3", "confidence")
    return [
        ("Difference map", difference_map(diff, grid, relief, arrays.get("filled_mask"), change=arrays.get("change"))),
        ("Histogram", histogram(diff, lod, conf)),
        ("Stable-ground residuals", residual_map(arrays.get("residual"), grid, relief)),
    ]


def uncertainty(report: dict) -> Table | None:
    """The uncertainty's scalar values (the nested ones are in report.json)."""
    u = report.get("uncertainty") or report.get("uncertainty_m3")
    return kv({k: v for k, v in u.items() if not isinstance(v, (dict, list))}) if isinstance(u, dict) else None


def render_html(report: dict, arrays: dict, grid: GridSpec, run_date: str | None = None) -> str:
    """The report as one HTML string (``run_date``: when the run ended; now when not given)."""
    return page.render(
        "report.html.j2",
        date=run_date or datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        version=fmt(get(report, "software", "version") or "unknown"),
        result=result(report, arrays),
        volumes=Table(["", "net", "cut", "fill", "area (m²)"], volume_rows(report)),
        quantities=earthworks.quantities(report),
        grade=earthworks.grade(report),
        figures=figures(report, arrays, grid),
        nonsoil_map=excluded.classes_map(arrays.get("classes"), grid, arrays.get("dem_after")),
        excluded=excluded.tables(report),
        uncertainty=uncertainty(report),
        correction=correction(report),
        reference=surface.section(report) if surface.is_surface(report) else None,
        registration=registration(report),
        inputs=inputs(report),
        parameters=parameters(report),
        holes=kv(report["holes"], 2) if isinstance(report.get("holes"), dict) else None,
        timings=kv(report.get("timings_s"), 2),
    )


def write_html(report: dict, arrays: dict, grid: GridSpec, path: str | Path) -> Path:
    """Write report.html atomically (options named in the text as spans naming them); returns its path."""
    return page.write(path, wording.html(render_html(report, arrays, grid)))


ZERO = 0.005  # m³: what "0.00" shows


def zero_notes(report: dict, arrays: dict, words: tuple[str, str, str] = ("", "cut", "fill")) -> list[tuple[str, str]]:
    """(word, why) per headline kind (cut, fill) that reads 0 while the compared cells hold some of
    that kind; none when none does. ``words``: the headline's (lead, cut, fill) words."""
    volumes, every = report.get("volume_m3") or {}, report.get("volume_all_cells_m3") or {}
    return [
        (word, _why(report, kind, sign, arrays))
        for kind, sign, word in (("cut", -1.0, words[1]), ("fill", 1.0, words[2]))
        if _number(shown := volumes.get(kind)) and abs(shown) < ZERO
        if _number(anywhere := every.get(kind)) and anywhere >= ZERO
    ]


def _why(report: dict, kind: str, sign: float, arrays: dict) -> str:
    lod = (report.get("uncertainty_m3") or {}).get("lod_m")
    cells = _left_out(arrays.get("difference"), arrays.get("change"), sign, lod)
    beyond = "lower" if sign < 0 else "higher"
    threshold = f"{sign * lod:+.2f} m" if _number(lod) else "their level of detection"
    level = f"{lod:.2f} m" if _number(lod) else "its level"
    text = (
        f"the headline counts only areas of significant change: at least {MIN_CELLS} touching measured cells "
        f"{beyond} than their level of detection ({level} on stable ground, more in a cell with few points or "
        f"a wide spread of heights), with a rim of {BUFFER_CELLS} cell; cells on the border of the compared area, "
        "only partly covered by a survey, never start one. "
    )
    if cells is not None and cells["count"]:
        parts = [
            f"{cells['border']} on the border",
            f"{cells['small']} in patches of fewer than {MIN_CELLS} such cells",
        ]
        parts += [f"{cells['raised']} within their own cell's higher level of detection"] if cells["raised"] else []
        text += (
            f"{cells['count']} cell{'s' if cells['count'] != 1 else ''} {'are' if cells['count'] != 1 else 'is'} "
            f"{beyond} than {threshold} (down to {cells['extreme']:+.2f} m on the map): " + ", ".join(parts) + ". "
        )
    elif cells is not None:
        text += f"No cell is {beyond} than {threshold} (the most: {cells['extreme']:+.2f} m): all of it is noise. "
    return text + _sums(report, kind)


def _sums(report: dict, kind: str) -> str:
    """Where the left-out change shows in the report's other sums, and which number to trust."""
    thresholded = (report.get("volume_thresholded_m3") or {}).get(kind)
    every = (report.get("volume_all_cells_m3") or {}).get(kind)
    unc = report.get("uncertainty_m3") or {}
    net, net_all = (report.get("volume_m3") or {}).get("net"), (report.get("volume_all_cells_m3") or {}).get("net")
    text = "Such cells count as survey noise"
    if _number(thresholded):
        text += f": {thresholded:,.2f} m³ if every cell beyond the level of detection were counted"
    text += f"; summed over every compared cell, noise included (the paper's sum), {kind} is {every:,.2f} m³. "
    if _number(net) and _number(net_all):
        text += (
            f"Trust the headline (net {net:+,.2f}{_pm(unc.get('net'))} m³): the every-cell net "
            f"({net_all:+,.2f}{_pm(unc.get('net_all_cells'))} m³) adds the noise and its wider interval."
        )
    return text


def _left_out(diff: Any, change: Any, sign: float, lod: Any) -> dict[str, Any] | None:
    """The cells of ``sign`` beyond the stable-ground LoD outside the change areas: how many, on
    the border of the compared area, in patches under MIN_CELLS, else (raised own LoD)."""
    from scipy import ndimage

    d = np.asarray(diff, dtype=float) if diff is not None else None
    if d is None or d.ndim != 2 or not _number(lod) or not np.isfinite(d).any():
        return None
    valid = np.isfinite(d)
    areas = np.asarray(change, dtype=bool) if change is not None and np.shape(change) == d.shape else False
    beyond = valid & (sign * np.where(valid, d, 0.0) > lod) & ~areas
    border = valid & ~ndimage.binary_erosion(valid, border_value=0)
    inner = beyond & ~border
    labels, n = ndimage.label(inner, structure=np.ones((3, 3), bool))
    small = np.isin(labels, 1 + np.flatnonzero(np.bincount(labels.ravel(), minlength=n + 1)[1:] < MIN_CELLS))
    extreme = float(np.nanmin(d) if sign < 0 else np.nanmax(d))
    count, on_border, in_small = int(beyond.sum()), int((beyond & border).sum()), int((inner & small).sum())
    raised = count - on_border - in_small
    return {"count": count, "border": on_border, "small": in_small, "raised": raised, "extreme": extreme}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def _pm(value: Any) -> str:
    return f" ± {value:,.2f}" if _number(value) else ""
