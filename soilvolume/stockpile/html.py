"""report.html of a stockpile inventory: one self-contained page, the piles' table and their
warnings (from report.json's dictionary, so both say the same)."""

from __future__ import annotations

import base64
import os
from html import escape
from pathlib import Path

#: the table's columns: (report.json key, heading)
COLUMNS = (
    ("name", "Pile"),
    ("volume_m3", "Volume (m³)"),
    ("interval_m3", "95 % interval (m³)"),
    ("area_m2", "Area (m²)"),
    ("max_height_m", "Max height (m)"),
    ("base", "Base"),
    ("tonnes", "Tonnes"),
)
STYLE = (
    "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
    "td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}td:first-child{text-align:left}"
)


def _cell(value) -> str:
    """One table cell's text."""
    if value is None:
        return "–"
    if isinstance(value, list):
        return " – ".join(_cell(v) for v in value)
    return escape(f"{value:,.1f}" if isinstance(value, float) else str(value))


def page(report: dict, png: bytes | None = None) -> str:
    """The page's HTML; ``png``: the map (:func:`.map.map_png`), embedded."""
    head = "".join(f"<th>{escape(h)}</th>" for _, h in COLUMNS)
    rows = "".join(
        "<tr>" + "".join(f"<td>{_cell(p.get(k))}</td>" for k, _ in COLUMNS) + "</tr>" for p in report["piles"]
    )
    how = "found in the survey" if report["piles_found"] else f"from {escape(str(report['piles_file']))}"
    warnings = "".join(f"<li>{escape(w)}</li>" for w in report["warnings"]) or "<li>none</li>"
    total = f"{report['volume_m3']:,.1f} m³" + (f", {report['tonnes']:,.1f} t" if report["tonnes"] is not None else "")
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Stockpile inventory</title>"
        f"<style>{STYLE}</style></head><body><h1>Stockpile inventory</h1>"
        f"<p>Survey {escape(report['survey'])}; {len(report['piles'])} piles {how}; cell {report['cell_m']} m; "
        f"base {escape(report['base'])}. Total {total}.</p>"
        f"<table><tr>{head}</tr>{rows}</table>{_map(png)}<h2>Warnings</h2><ul>{warnings}</ul></body></html>"
    )


def _map(png: bytes | None) -> str:
    """The map's figure (none without a map)."""
    if png is None:
        return ""
    uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    caption = "The survey's hillshade (north up; white: no height), each pile's polygon outlined in red."
    return f"<h2>Map</h2><figure><img src='{uri}' alt='map of the piles'><figcaption>{caption}</figcaption></figure>"


def write_html(path: str | Path, report: dict, png: bytes | None = None) -> Path:
    """Write report.html beside its destination and rename it into place."""
    path = Path(path)
    part = path.with_name(f".{path.name}.part")
    part.write_text(page(report, png), encoding="utf-8")
    os.replace(part, path)
    return path
