"""The histogram of the difference in report.html, as inline SVG (with the level of detection
marked)."""

from __future__ import annotations

import html
import math

import numpy as np
from markupsafe import Markup

from .figures import RDBU, _float_2d, _positive, colour_ramp
from .svgparts import count_label, halo, round_ticks, tick_label

_HIST_BINS = 71


def _lod_marks(sx, top: float, ph: float, right: float, lod: float, label: str) -> tuple[list[str], str]:
    """The shaded ±LoD band with its dashed edges, and its key at the top right of the plot (``sx``: x in
    metres -> px; ``right``: the plot's right edge)."""
    band = (
        f'<rect x="{sx(-lod):.1f}" y="{top}" width="{sx(lod) - sx(-lod):.1f}" height="{ph}" '
        'fill="#f39c12" fill-opacity=".3"/>'
    )
    edges = [
        f'<line x1="{sx(x):.1f}" x2="{sx(x):.1f}" y1="{top}" y2="{top + ph}" stroke="#d35400" stroke-dasharray="4 3"/>'
        for x in (-lod, lod)
    ]
    key = (
        f'<rect x="{right - 22}" y="{top + 8}" width="14" height="12" fill="#f39c12" '
        f'fill-opacity=".5"/><text x="{right - 28}" y="{top + 18}" text-anchor="end" '
        f"{halo(12)}>{html.escape(label)}</text>"
    )
    return [band, *edges], key


def _hist_svg(counts: np.ndarray, lim: float, lod: float | None, lod_label: str, ident: str) -> str:
    """Log-count bars over [-lim, lim], ±LoD band, zero line, axes with ticks."""
    w, h, left, right, top, bottom = 760, 300, 64, 16, 12, 50
    pw, ph = w - left - right, h - top - bottom
    y_hi = math.log10(max(int(counts.max()), 1)) + 0.15
    y_lo = math.log10(0.5)

    def sx(x: float) -> float:
        return left + (min(max(x, -lim), lim) + lim) / (2 * lim) * pw

    def sy(c: float) -> float:
        return top + ph * (1 - (math.log10(c) - y_lo) / (y_hi - y_lo))

    n = len(counts)
    edges = np.linspace(-lim, lim, n + 1)
    fills = colour_ramp((edges[:-1] + edges[1:]) / 2, lim, RDBU)
    parts = [
        f'<line x1="{left}" x2="{left + pw}" y1="{sy(10**p):.1f}" y2="{sy(10**p):.1f}" stroke="#e4e4e4"/>'
        f'<text x="{left - 6}" y="{sy(10**p) + 4:.1f}" text-anchor="end">{count_label(10**p)}</text>'
        for p in range(0, math.floor(y_hi) + 1)
    ]
    parts += [
        f'<rect class=bar x="{sx(edges[i]):.2f}" y="{sy(c):.1f}" width="{pw / n:.2f}" '
        f'height="{top + ph - sy(c):.1f}" fill="rgb({r},{g},{b})" stroke="#555" stroke-width=".5"/>'
        for i, c in enumerate(counts.tolist())
        if c > 0
        for r, g, b in [fills[i, :3].tolist()]
    ]
    band, key = _lod_marks(sx, top, ph, left + pw, lod, lod_label) if lod else ([], "")
    parts += band
    ticks, step = round_ticks(-lim, lim, 8)
    parts += [
        f'<line x1="{sx(t):.1f}" x2="{sx(t):.1f}" y1="{top + ph}" y2="{top + ph + 5}" stroke="#000"/>'
        f'<text x="{sx(t):.1f}" y="{top + ph + 18}" text-anchor="middle">{tick_label(t, step)}</text>'
        for t in ticks
    ]
    parts.append(
        f'<line x1="{sx(0):.1f}" x2="{sx(0):.1f}" y1="{top}" y2="{top + ph}" stroke="#000" '
        'stroke-width="1.2"/>'
        f'<path d="M{left},{top}V{top + ph}H{left + pw}" fill="none" stroke="#000"/>'
        f'<text x="{left + pw / 2}" y="{h - 8}" text-anchor="middle">after − before (m)</text>'
        f'<text transform="translate(16,{top + ph / 2}) rotate(-90)" text-anchor="middle">'
        "cells (log scale)</text>"
    )
    parts.append(key)
    return (
        f'<svg class=plot id="{ident}" viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-size="12" '
        f'role="img"><title>Histogram of after − before differences</title>{"".join(parts)}</svg>'
    )


def histogram(
    diff: np.ndarray, lod: float | None = None, confidence: float | None = None, ident: str = "histogram"
) -> Markup | None:
    """HTML figure: inline-SVG histogram of the finite differences with the ±LoD band shaded; None
    without data."""
    d = _float_2d(diff)
    if d is None:
        return None
    v = d[np.isfinite(d)]
    lod = _positive(lod)
    lo, hi = np.percentile(v[:: max(1, v.size // 250_000)], [0.5, 99.5])  # of a subsample; wide enough for ±1.5 LoD
    lim = max(abs(float(lo)), abs(float(hi)), 1.5 * (lod or 0.0), 1e-3)
    counts, _ = np.histogram(v, bins=_HIST_BINS, range=(-lim, lim))
    conf = _positive(confidence)
    label = f"±LoD{f'{conf * 100:g}' if conf and conf < 1 else ''} = {lod:.3f} m" if lod else ""
    hidden = v.size - int(counts.sum())
    caption = (
        f"{v.size:,} cells in {_HIST_BINS} bins of {2 * lim / _HIST_BINS:.3g} m over ±{lim:.3g} m "
        f"(0.5–99.5th percentiles){f'; {hidden:,} cells beyond not shown' if hidden else ''}. "
        + ("Shaded: level of detection." if lod else "No level of detection in the report.")
    )
    return Markup(f"<figure>{_hist_svg(counts, lim, lod, label, ident)}<figcaption>{caption}</figcaption></figure>")
