"""The pieces of report.html's figures: round ticks and their labels, a map's figure (its PNG
embedded, its scale bar, north arrow and colour bar drawn by ``templates/figures.html.j2``)."""

from __future__ import annotations

import base64
import math

import numpy as np
from markupsafe import Markup

from ..core.types import GridSpec
from . import page
from .raster import png_bytes

DISPLAY = 760  # longest side of a map on the page (CSS px)


def nice_length(span: float) -> float:
    """The largest 1/2/5 x 10^n not longer than a quarter of ``span``."""
    raw = span / 4
    base = 10 ** math.floor(math.log10(raw))
    return max(m * base for m in (1, 2, 5) if m * base <= raw)


def round_ticks(lo: float, hi: float, n: int = 5) -> tuple[list[float], float]:
    """About ``n`` round tick values in [lo, hi] and their step."""
    raw = (hi - lo) / n
    base = 10 ** math.floor(math.log10(raw))
    step = next(m * base for m in (1, 2, 5, 10) if m * base >= raw * 0.999)
    first = math.ceil(lo / step - 1e-9)
    return [i * step for i in range(first, math.floor(hi / step + 1e-9) + 1)], step


def tick_label(v: float, step: float) -> str:
    digits = max(0, -math.floor(math.log10(step) + 1e-9))
    s = f"{v:.{digits}f}"
    return "0" if float(s) == 0 else s.replace("-", "−")


def labelled(lo: float, hi: float, n: int) -> list[tuple[float, str]]:
    """About ``n`` round ticks in [lo, hi] with their labels."""
    ticks, step = round_ticks(lo, hi, n)
    return [(t, tick_label(t, step)) for t in ticks]


def metres(length: float) -> str:
    return f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"


def count_label(c: float) -> str:
    for div, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if c >= div:
            return f"{c / div:g}{unit}"
    return f"{c:g}"


def colour_bar(table: np.ndarray, limit: float, label: str, ident: str, ends: tuple[str, str] = ("", "")) -> str:
    """A horizontal SVG colour bar from -limit to +limit with ticks in metres."""
    ticks = [(30 + (t + limit) / (2 * limit) * 420, text) for t, text in labelled(-limit, limit, 4)]
    return page.macro("colour_bar", table=table, label=label, ident=ident, ends=ends, ticks=ticks)


def extent_text(grid: GridSpec, shape: tuple[int, int], k: int) -> str:
    u = grid.xy_unit or 1.0
    x0, y1 = grid.xmin / u, grid.ymax / u
    x1, y0 = x0 + shape[1] * grid.cell / u, y1 - shape[0] * grid.cell / u
    unit = "m" if u == 1 else "CRS units"
    shown = f", shown as {k} x {k} cell means" if k > 1 else ""
    return (
        f"Extent x {x0:,.1f} – {x1:,.1f}, y {y0:,.1f} – {y1:,.1f} ({unit}); "
        f"{shape[0]:,} x {shape[1]:,} cells of {grid.cell:g} m{shown}."
    )


def map_figure(ident: str, title: str, rgba: np.ndarray, span_m: float, colour_bar: str, caption: str) -> str:
    """The PNG map with a scale bar and north arrow overlaid, its colour bar and caption."""
    h, w = rgba.shape[:2]
    s = DISPLAY / max(h, w)
    wd, hd, length = round(w * s), round(h * s), nice_length(span_m)
    uri = "data:image/png;base64," + base64.b64encode(png_bytes(rgba)).decode("ascii")
    size = {"w": w, "h": h, "wd": wd, "hd": hd, "metres": metres(length), "px": length / span_m * wd}
    return page.macro(
        "map_figure", ident=ident, title=title, uri=uri, **size, caption=Markup(caption), colour_bar=Markup(colour_bar)
    )
