"""A cross-section's picture as a standalone SVG: the before (or design) and after heights over
the chainage, the ground between them shaded as cut (after below before) or fill (above), axes
with round ticks labelled in metres (:mod:`.svgparts`); drawn in the run's own process."""

from __future__ import annotations

import html

import numpy as np

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


def _axes(xticks: tuple, yticks: tuple, sx, sy) -> list[str]:
    (xs, xstep), (ys, ystep) = xticks, yticks
    bottom = H - BOTTOM
    parts = [
        f'<line x1="{LEFT}" x2="{W - RIGHT}" y1="{sy(t):.1f}" y2="{sy(t):.1f}" stroke="#e4e4e4"/>'
        f'<text x="{LEFT - 6}" y="{sy(t) + 4:.1f}" text-anchor="end">{tick_label(t, ystep)}</text>'
        for t in ys
    ]
    parts += [
        f'<line x1="{sx(t):.1f}" x2="{sx(t):.1f}" y1="{bottom}" y2="{bottom + 4}" stroke="#000"/>'
        f'<text x="{sx(t):.1f}" y="{bottom + 17}" text-anchor="middle">{tick_label(t, xstep)}</text>'
        for t in xs
    ]
    parts.append(
        f'<rect x="{LEFT}" y="{TOP}" width="{W - LEFT - RIGHT}" height="{H - TOP - BOTTOM}" fill="none" stroke="#000"/>'
    )
    parts.append(f'<text x="{(LEFT + W - RIGHT) / 2}" y="{H - 8}" text-anchor="middle">chainage (m)</text>')
    parts.append(
        f'<text transform="translate(16,{(TOP + H - BOTTOM) / 2}) rotate(-90)" text-anchor="middle">height (m)</text>'
    )
    return parts


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of consecutive True values."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], ok.astype(np.int8), [0]))))
    return list(zip(edges[::2], edges[1::2], strict=True))


def _shading(chainage: np.ndarray, before: np.ndarray, after: np.ndarray, sx, sy) -> list[str]:
    """Polygons between the two lines, one per run of samples of one sign (cut or fill)."""
    d = after - before
    parts = []
    for kind, ok in (("fill", d > 0), ("cut", d < 0)):
        for a, b in _runs(ok & np.isfinite(d)):
            top = [f"{sx(c):.1f},{sy(z):.1f}" for c, z in zip(chainage[a:b], after[a:b], strict=True)]
            low = [f"{sx(c):.1f},{sy(z):.1f}" for c, z in zip(chainage[a:b], before[a:b], strict=True)]
            points = " ".join(top + low[::-1])
            parts.append(f'<polygon points="{points}" fill="{COLOURS[kind]}" fill-opacity=".35" stroke="none"/>')
    return parts


def _line(chainage: np.ndarray, z: np.ndarray, colour: str, sx, sy, dash: str = "") -> list[str]:
    """A polyline per run of samples with a height (no line drawn across a gap)."""
    style = f' stroke-dasharray="{dash}"' if dash else ""
    out = []
    for a, b in _runs(np.isfinite(z)):
        points = " ".join(f"{sx(c):.1f},{sy(h):.1f}" for c, h in zip(chainage[a:b], z[a:b], strict=True))
        out.append(f'<polyline points="{points}" fill="none" stroke="{colour}" stroke-width="1.6"{style}/>')
    return out


def profile_svg(name: str, chainage: np.ndarray, before: np.ndarray, after: np.ndarray, label: str = "before") -> str:
    """The SVG document of one section (``label``: what the before heights are: before or design)."""
    xticks, yticks, sx, sy = _scales(chainage, np.concatenate([before, after]))
    parts = _axes(xticks, yticks, sx, sy) + _shading(chainage, before, after, sx, sy)
    parts += _line(chainage, before, COLOURS["before"], sx, sy, "6 3")
    parts += _line(chainage, after, COLOURS["after"], sx, sy)
    legend = [(label, COLOURS["before"])] + [(k, COLOURS[k]) for k in ("after", "cut", "fill")]
    parts += [
        f'<rect x="{LEFT + 8 + 90 * k}" y="12" width="12" height="12" fill="{c}"/>'
        f'<text x="{LEFT + 24 + 90 * k}" y="22">{html.escape(t)}</text>'
        for k, (t, c) in enumerate(legend)
    ]
    parts.append(f'<text x="{W - RIGHT}" y="22" text-anchor="end" font-weight="bold">{html.escape(name)}</text>')
    title = html.escape(f"Section {name}")
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" width="{W}" height="{H}" '
        f'font-family="sans-serif" font-size="12" role="img" aria-label="{title}"><title>{title}</title>'
        f'<rect width="{W}" height="{H}" fill="#fff"/>{"".join(parts)}</svg>\n'
    )
