"""report.html of a series (``templates/series.html.j2``): the ledger, the cumulative cut and fill
chart (inline SVG), the epochs' registrations and each period's difference map."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
from markupsafe import Markup

from ..core.types import GridSpec
from . import page
from .figures import difference_map
from .seriesgrade import progress_table
from .svgparts import round_ticks
from .text import fmt, pm

SERIES_COLOURS = {"cut": "#c0392b", "fill": "#2471a3", "net": "#222"}


def running_totals(report: dict) -> dict[str, list[float]]:
    """Cut and fill moved since E0 (running sums of the periods'), and the net from E0 to each
    epoch (the running sum of the periods' nets: the cumulative's at the end)."""
    out = {"cut": [0.0], "fill": [0.0], "net": [0.0]}
    for p in report["periods"]:
        for k in out:
            out[k].append(out[k][-1] + p["volume_m3"][k])
    return out


def chart_svg(report: dict) -> Markup:
    """Cumulative cut, fill and net (m3) against the epochs (their dates where known)."""
    totals = running_totals(report)
    w, h, left, right, top, bottom = 760, 300, 72, 120, 14, 52
    pw, ph = w - left - right, h - top - bottom
    n = len(totals["net"]) - 1
    lo = min(0.0, min(totals["net"]), -max(totals["cut"]))
    hi = max(1.0, max(totals["fill"]), max(totals["net"]))
    ticks, _ = round_ticks(lo, hi, 6)
    lo, hi = min(lo, ticks[0]), max(hi, ticks[-1])

    def sx(k: float) -> float:
        return left + pw * k / max(n, 1)

    def sy(v: float) -> float:
        return top + ph * (1 - (v - lo) / (hi - lo))

    parts = [
        f'<line x1="{left}" x2="{left + pw}" y1="{sy(t):.1f}" y2="{sy(t):.1f}" stroke="#e4e4e4"/>'
        f'<text x="{left - 6}" y="{sy(t) + 4:.1f}" text-anchor="end">{t:,.0f}</text>'
        for t in ticks
    ]
    for k, e in enumerate(report["epochs"]):
        name = html.escape(e.get("date") or f"E{k}")
        parts.append(f'<text x="{sx(k):.1f}" y="{top + ph + 18}" text-anchor="middle">{name}</text>')
    for key, sign in (("fill", 1.0), ("cut", -1.0), ("net", 1.0)):
        pts = " ".join(f"{sx(k):.1f},{sy(sign * v):.1f}" for k, v in enumerate(totals[key]))
        colour = SERIES_COLOURS[key]
        parts.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
        parts += [f'<circle cx="{p.split(",")[0]}" cy="{p.split(",")[1]}" r="3" fill="{colour}"/>' for p in pts.split()]
        label = {"fill": "fill (added)", "cut": "cut (removed)", "net": "net since E0"}[key]
        y_end = sy(sign * totals[key][-1])
        parts.append(f'<text x="{left + pw + 6}" y="{y_end + 4:.1f}" fill="{colour}">{label}</text>')
    parts.append(f'<line x1="{left}" x2="{left + pw}" y1="{sy(0):.1f}" y2="{sy(0):.1f}" stroke="#888"/>')
    parts.append(f'<text x="14" y="{top + ph / 2:.0f}" transform="rotate(-90 14 {top + ph / 2:.0f})">m³</text>')
    return Markup(
        f'<figure><svg class=plot viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-size="12">'
        + "".join(parts)
        + "</svg><figcaption>Cumulative cut and fill since the first survey (running sums of the "
        "periods', cut drawn below 0), and the net change from the first survey to each epoch (its "
        "last point is the cumulative net).</figcaption></figure>"
    )


def _changes(report: dict) -> list[tuple[str, dict]]:
    """(name, entry) of each period and of the cumulative."""
    return [(f"{k + 1}", p) for k, p in enumerate(report["periods"])] + [("cumulative", report["cumulative"])]


def ledger(report: dict) -> list[dict]:
    """A row per period and the cumulative: epochs, dates, net/cut/fill with their ±, verdict, reasons."""
    rows = []
    for name, p in _changes(report):
        v, u, q = p["volume_m3"], p["uncertainty_m3"], p.get("quality") or {}
        rows.append(
            {
                "name": f"{name}: E{p['from']} → E{p['to']}",
                "short": f"{name} (E{p['from']} → E{p['to']})",
                "dates": " → ".join(d or "?" for d in p["dates"]),
                "volumes": [pm(v[k], u[k]) for k in ("net", "cut", "fill")] + [fmt(v["below_detection"])],
                "verdict": str(q.get("verdict") or "–"),
                "reasons": [str(m) for m in q.get("messages") or []],
            }
        )
    return rows


def epochs(report: dict) -> list[dict]:
    """A row per epoch: date and where it came from, file, points, registration into E0."""
    rows = []
    for e in report["epochs"]:
        r = e["registration"]
        rot = "reference" if r.get("reference") else f"{fmt(r.get('rotation_deg'), 3)}° / {fmt(r.get('shift_m'), 3)} m"
        source = e.get("date_source") if e.get("date") else None
        cells = [Path(e["path"]).name, fmt(e["points"]), rot]
        rows.append({"name": f"E{e['index']}", "date": e.get("date") or "–", "source": source, "cells": cells})
    return rows


def render_series_html(report: dict, series, grid: GridSpec, relief: np.ndarray) -> str:
    """The page of ``series`` (its periods and cumulative with their differences)."""
    maps = [
        (t, difference_map(c.diff, grid, relief, series.refilled, t, f"diff-{c.start}-{c.end}"))
        for c in [*series.periods, series.cumulative]
        for t in [f"E{c.end} − E{c.start}"]
    ]
    return page.render(
        "series.html.j2",
        version=fmt(report["software"]["version"]),
        confidence=fmt(100 * report["options"]["lod_confidence"], 0),
        ledger=ledger(report),
        chart=chart_svg(report),
        epochs=epochs(report),
        progress=progress_table(report),
        figures=maps,
    )


def write_series_html(path: Path, report: dict, series, grid: GridSpec, relief: np.ndarray) -> Path:
    """Write report.html atomically."""
    return page.write(path, render_series_html(report, series, grid, relief))
