"""The histogram of the difference in report.html, as inline SVG (``templates/figures.html.j2``),
the level of detection marked."""

from __future__ import annotations

import math

import numpy as np

from . import page
from .figures import RDBU, _float_2d, _positive, colour_ramp
from .svgparts import count_label, labelled

_HIST_BINS = 71
FRAME = {"left": 64, "top": 12, "pw": 680, "ph": 238}  # the plot's left and top edge, width and height (px)


def _hist_limit(v: np.ndarray, lod: float | None) -> float:
    """Symmetric histogram range: the 0.5-99.5 percentiles (of a subsample), wide enough for ±1.5 LoD."""
    lo, hi = np.percentile(v[:: max(1, v.size // 250_000)], [0.5, 99.5])
    return max(abs(float(lo)), abs(float(hi)), 1.5 * (lod or 0.0), 1e-3)


def _hist_svg(counts: np.ndarray, lim: float, lod: float | None, lod_label: str, ident: str) -> str:
    """Log-count bars over [-lim, lim], ±LoD band, zero line, axes with ticks."""
    left, top, pw, ph = FRAME.values()
    y_hi, y_lo = math.log10(max(int(counts.max()), 1)) + 0.15, math.log10(0.5)

    def sx(x: float) -> float:
        return left + (min(max(x, -lim), lim) + lim) / (2 * lim) * pw

    def sy(c: float) -> float:
        return top + ph * (1 - (math.log10(c) - y_lo) / (y_hi - y_lo))

    edges = np.linspace(-lim, lim, len(counts) + 1)
    fills = colour_ramp((edges[:-1] + edges[1:]) / 2, lim, RDBU)[:, :3].tolist()
    bars = [(sx(edges[i]), sy(c), fills[i]) for i, c in enumerate(counts.tolist()) if c > 0]
    grid = [(sy(10**p), count_label(10**p)) for p in range(0, math.floor(y_hi) + 1)]
    ticks = [(sx(t), text) for t, text in labelled(-lim, lim, 8)]
    band = (sx(-lod), sx(lod), lod_label) if lod else None
    return page.macro(
        "histogram", ident=ident, n=len(counts), zero=sx(0), grid=grid, bars=bars, band=band, ticks=ticks, **FRAME
    )


def histogram(
    diff: np.ndarray, lod: float | None = None, confidence: float | None = None, ident: str = "histogram"
) -> str | None:
    """HTML figure: inline-SVG histogram of the finite differences with the ±LoD band shaded; None
    without data."""
    d = _float_2d(diff)
    if d is None:
        return None
    v = d[np.isfinite(d)]
    lod = _positive(lod)
    lim = _hist_limit(v, lod)
    counts, _ = np.histogram(v, bins=_HIST_BINS, range=(-lim, lim))
    conf = _positive(confidence)
    label = f"±LoD{f'{conf * 100:g}' if conf and conf < 1 else ''} = {lod:.3f} m" if lod else ""
    hidden = v.size - int(counts.sum())
    caption = (
        f"{v.size:,} cells in {_HIST_BINS} bins of {2 * lim / _HIST_BINS:.3g} m over ±{lim:.3g} m "
        f"(0.5–99.5th percentiles){f'; {hidden:,} cells beyond not shown' if hidden else ''}. "
        + ("Shaded: level of detection." if lod else "No level of detection in the report.")
    )
    return f"<figure>{_hist_svg(counts, lim, lod, label, ident)}<figcaption>{caption}</figcaption></figure>"
