"""report.html of a series (``templates/series.html.j2``): the ledger, the cumulative cut and fill
chart (inline SVG), the epochs' registrations and each period's difference map."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.types import GridSpec
from . import page
from .figures import difference_map
from .seriesgrade import progress_table
from .svgparts import round_ticks
from .text import fmt, pm

#: the chart's lines: total, its sign on the chart, colour, label
LINES = (
    ("fill", 1.0, "#2471a3", "fill (added)"),
    ("cut", -1.0, "#c0392b", "cut (removed)"),
    ("net", 1.0, "#222", "net since E0"),
)


def chart(report: dict) -> dict:
    """Cumulative cut, fill and net (m3) against the epochs (their dates where known): the pixel
    positions the template draws (the plot 568 x 234 px at (72, 14) of 760 x 300). Cut and fill are
    running sums of the periods', the net at each epoch that of their nets (the cumulative's at the end)."""
    totals = {"cut": [0.0], "fill": [0.0], "net": [0.0]}
    for p in report["periods"]:
        for k, run in totals.items():
            run.append(run[-1] + p["volume_m3"][k])
    n = len(totals["net"]) - 1
    lo = min(0.0, min(totals["net"]), -max(totals["cut"]))
    hi = max(1.0, max(totals["fill"]), max(totals["net"]))
    ticks, _ = round_ticks(lo, hi, 6)
    lo, hi = min(lo, ticks[0]), max(hi, ticks[-1])

    def sy(v: float) -> float:
        return 14 + 234 * (1 - (v - lo) / (hi - lo))

    xs = [72 + 568 * k / max(n, 1) for k in range(n + 1)]
    names = [e.get("date") or f"E{k}" for k, e in enumerate(report["epochs"])]
    lines = [
        (c, label, [(x, sy(sign * v)) for x, v in zip(xs, totals[key], strict=True)]) for key, sign, c, label in LINES
    ]
    ticks = [(t, sy(t)) for t in ticks]
    return {"ticks": ticks, "epochs": list(zip(xs, names, strict=True)), "lines": lines, "zero": sy(0)}


def changes(report: dict) -> list[tuple[str, dict]]:
    """(name, entry) of each period (its number) and of the cumulative."""
    return [(f"{k + 1}", p) for k, p in enumerate(report["periods"])] + [("cumulative", report["cumulative"])]


def write_series_html(path: Path, report: dict, series, grid: GridSpec, relief: np.ndarray) -> Path:
    """Write the page of ``series`` (its periods and cumulative with their differences) atomically."""
    maps = [
        (t, difference_map(c.diff, grid, relief, series.refilled, t, f"diff-{c.start}-{c.end}"))
        for c in [*series.periods, series.cumulative]
        for t in [f"E{c.end} − E{c.start}"]
    ]
    text = page.render(
        "series.html.j2",
        fmt=fmt,
        pm=pm,
        version=fmt(report["software"]["version"]),
        confidence=fmt(100 * report["options"]["lod_confidence"], 0),
        ledger=changes(report),
        chart=chart(report),
        epochs=report["epochs"],
        file_name=lambda path: Path(path).name,
        progress=progress_table(report),
        figures=maps,
    )
    return page.write(path, text)
