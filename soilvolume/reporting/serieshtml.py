"""report.html of a series run: the ledger, the cumulative cut and fill over time as an inline SVG
chart, the epochs' registrations and each period's difference map (:mod:`.figures`)."""

from __future__ import annotations

import html
import os
from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from .figures import _ticks, difference_map
from .html import _CSS, _fmt, _pm, _table

SERIES_COLOURS = {"cut": "#c0392b", "fill": "#2471a3", "net": "#222"}


def running_totals(report: dict) -> dict[str, list[float]]:
    """Cut and fill moved since E0 (running sums of the periods'), and the net from E0 to each
    epoch (the running sum of the periods' nets: the cumulative's at the end)."""
    out = {"cut": [0.0], "fill": [0.0], "net": [0.0]}
    for p in report["periods"]:
        for k in out:
            out[k].append(out[k][-1] + p["volume_m3"][k])
    return out


def chart_svg(report: dict) -> str:
    """Cumulative cut, fill and net (m3) against the epochs (their dates where known)."""
    totals = running_totals(report)
    w, h, left, right, top, bottom = 760, 300, 72, 120, 14, 52
    pw, ph = w - left - right, h - top - bottom
    n = len(totals["net"]) - 1
    lo = min(0.0, min(totals["net"]), -max(totals["cut"]))
    hi = max(1.0, max(totals["fill"]), max(totals["net"]))
    ticks, _ = _ticks(lo, hi, 6)
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
    return (
        f'<figure><svg class=plot viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-size="12">'
        + "".join(parts)
        + "</svg><figcaption>Cumulative cut and fill since the first survey (running sums of the "
        "periods', cut drawn below 0), and the net change from the first survey to each epoch (its "
        "last point is the cumulative net).</figcaption></figure>"
    )


def _changes(report: dict) -> list[tuple[str, dict]]:
    """(name, entry) of each period and of the cumulative."""
    return [(f"{k + 1}", p) for k, p in enumerate(report["periods"])] + [("cumulative", report["cumulative"])]


def _ledger(report: dict) -> str:
    rows = []
    for name, p in _changes(report):
        v, u = p["volume_m3"], p["uncertainty_m3"]
        dates = "<span style='white-space:nowrap'>" + " → ".join(html.escape(d or "?") for d in p["dates"]) + "</span>"
        rows.append(
            [f"{name}: E{p['from']} → E{p['to']}", dates]
            + [_pm(v[k], u[k]) for k in ("net", "cut", "fill")]
            + [_fmt(v["below_detection"]), _verdict(p)]
        )
    head = ["period", "dates", "net (m³)", "cut (m³)", "fill (m³)", "of the net below detection (m³)", "quality"]
    return "<h2>Ledger</h2>" + _table(head, rows) + _reasons(report)


def _verdict(entry: dict) -> str:
    said = html.escape(str((entry.get("quality") or {}).get("verdict") or "–"))
    return f"<span class='verdict {said.replace(' ', '-')}'>{said}</span>"


def _reasons(report: dict) -> str:
    """Each period's quality verdict with its reasons, as a pair's report gives them."""
    items = []
    for name, p in _changes(report):
        q = p.get("quality") or {}
        reasons = "".join(f"<li>{html.escape(str(m))}</li>" for m in q.get("messages") or [])
        items.append(f"<li>{name} (E{p['from']} → E{p['to']}): {_verdict(p)}<ul>{reasons}</ul></li>")
    return "<h3>Quality of each period</h3><ul>" + "".join(items) + "</ul>"


def _epochs(report: dict) -> str:
    rows = []
    for e in report["epochs"]:
        r = e["registration"]
        rot = (
            "reference" if r.get("reference") else f"{_fmt(r.get('rotation_deg'), 3)}° / {_fmt(r.get('shift_m'), 3)} m"
        )
        when = html.escape(e.get("date") or "–")
        if e.get("date") and e.get("date_source"):
            when += f" <span class=note>({html.escape(e['date_source'])})</span>"
        rows.append([f"E{e['index']}", when, html.escape(Path(e["path"]).name), _fmt(e["points"]), rot])
    head = ["epoch", "date (from)", "file", "points", "registration into E0 (rotation / shift)"]
    return "<h2>Epochs</h2>" + _table(head, rows)


def render_series_html(report: dict, series, grid: GridSpec, relief: np.ndarray) -> str:
    title = "Soil volume change over a series of surveys"
    parts = [
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title><style>{_CSS}</style>"
        f"</head><body><h1>{title}</h1><p class=note>soilvolume {_fmt(report['software']['version'])}; "
        f"± at {_fmt(100 * report['options']['lod_confidence'], 0)} % confidence. The periods add up to "
        "the cumulative net.</p>",
        _ledger(report),
        "<h2>Cut and fill over time</h2>",
        chart_svg(report),
        _epochs(report),
        "<h2>Differences</h2>",
    ]
    for c in [*series.periods, series.cumulative]:
        title_c = f"E{c.end} − E{c.start}"
        fig = difference_map(c.diff, grid, relief, series.refilled, title_c, f"diff-{c.start}-{c.end}")
        parts.append(fig or f"<p class=note>{title_c}: no data</p>")
    return "\n".join(parts) + "</body></html>"


def write_series_html(path: Path, report: dict, series, grid: GridSpec, relief: np.ndarray) -> Path:
    """Write report.html atomically."""
    text = render_series_html(report, series, grid, relief)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
