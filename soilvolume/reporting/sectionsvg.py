"""A cross-section's picture as a standalone SVG: the before (or design) and after heights over
the chainage, the ground between them shaded as cut (after below before) or fill (above), axes
with round ticks labelled in metres; drawn by ``templates/figures.html.j2`` in the run's own process."""

from __future__ import annotations

import numpy as np

from . import page
from .svgparts import round_ticks, tick_label

COLOURS = {"before": "#555", "after": "#111", "cut": "#c0392b", "fill": "#2471a3"}
W, H, LEFT, RIGHT, TOP, BOTTOM = 760, 320, 70, 20, 34, 48


def _scales(chainage: np.ndarray, heights: np.ndarray) -> tuple:
    """The x and y ticks and the functions from chainage and height to the picture's pixels."""
    xs, xstep = round_ticks(0.0, max(float(chainage[-1]), 1e-3), 6)
    finite = heights[np.isfinite(heights)]
    lo, hi = float(finite.min()), float(finite.max())
    pad = max(0.05 * (hi - lo), 0.05)
    ys, ystep = round_ticks(lo - pad, hi + pad, 5)
    lo, hi = min(lo - pad, ys[0]), max(hi + pad, ys[-1])
    x1 = max(float(chainage[-1]), xs[-1], 1e-3)
    pw, ph = W - LEFT - RIGHT, H - TOP - BOTTOM

    def sx(c: float) -> float:
        return LEFT + pw * c / x1

    def sy(z: float) -> float:
        return TOP + ph * (1 - (z - lo) / (hi - lo))

    return (xs, xstep), (ys, ystep), sx, sy


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of consecutive True values."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], ok.astype(np.int8), [0]))))
    return list(zip(edges[::2], edges[1::2], strict=True))


def profile_svg(name: str, chainage: np.ndarray, before: np.ndarray, after: np.ndarray, label: str = "before") -> str:
    """The SVG document of one section (``label``: what the before heights are: before or design)."""
    (xs, xstep), (ys, ystep), sx, sy = _scales(chainage, np.concatenate([before, after]))

    def points(z: np.ndarray, a: int, b: int) -> list[str]:
        return [f"{sx(c):.1f},{sy(h):.1f}" for c, h in zip(chainage[a:b], z[a:b], strict=True)]

    d = after - before
    shading = [  # between the two lines, one polygon per run of samples of one sign (cut or fill)
        (COLOURS[kind], " ".join(points(after, a, b) + points(before, a, b)[::-1]))
        for kind, ok in (("fill", d > 0), ("cut", d < 0))
        for a, b in _runs(ok & np.isfinite(d))
    ]
    lines = [  # a polyline per run of samples with a height (no line drawn across a gap)
        (COLOURS[key], dash, " ".join(points(z, a, b)))
        for key, z, dash in (("before", before, "6 3"), ("after", after, ""))
        for a, b in _runs(np.isfinite(z))
    ]
    legend = [(label, COLOURS["before"])] + [(k, COLOURS[k]) for k in ("after", "cut", "fill")]
    ygrid, xticks = [(sy(t), tick_label(t, ystep)) for t in ys], [(sx(t), tick_label(t, xstep)) for t in xs]
    frame = {"w": W, "h": H, "left": LEFT, "right": RIGHT, "top": TOP, "bottom": BOTTOM}
    svg = page.macro(
        "section", name=name, ygrid_=ygrid, xticks_=xticks, shading=shading, lines=lines, legend=legend, **frame
    )
    return svg + "\n"
