"""A self-contained report.html: maps as embedded PNGs coloured and hillshaded in numpy (encoded with
zlib, no plotting library), colour bars, scale bars, north arrows and the histogram as inline SVG;
tables of volumes, uncertainty, registration, inputs and timings. No network access, no scripts,
tolerant of missing report keys and arrays."""

from __future__ import annotations

import base64
import html
import math
import os
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from .types import GridSpec

_CSS = """body{font-family:sans-serif;margin:1.5em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.2em}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}img{max-width:100%;display:block}
h2{border-bottom:1px solid #ccc;margin-top:1.5em}.note{color:#666;font-size:90%}
figure{margin:.5em 0 1.2em}figcaption{color:#666;font-size:90%;margin-top:.3em;max-width:760px}
.map{position:relative;max-width:100%;outline:1px solid #999;
background:repeating-linear-gradient(45deg,#fff 0 4px,#ddd 4px 6px)}
.map img{width:100%;height:auto}.map svg{position:absolute;left:0;top:0;width:100%;height:100%}
svg.plot{display:block;max-width:100%;height:auto;font-family:sans-serif}"""

# ColorBrewer 11-class ramps, low -> high (as matplotlib's RdBu / PuOr): red = cut, blue = fill.
RDBU = np.array([[103, 0, 31], [178, 24, 43], [214, 96, 77], [244, 165, 130], [253, 219, 199],
                 [247, 247, 247], [209, 229, 240], [146, 197, 222], [67, 147, 195], [33, 102, 172],
                 [5, 48, 97]], float)
PUOR = np.array([[127, 59, 8], [179, 88, 6], [224, 130, 20], [253, 184, 99], [254, 224, 182],
                 [247, 247, 247], [216, 218, 235], [178, 171, 210], [128, 115, 172], [84, 39, 136],
                 [45, 0, 75]], float)
_MAX_PX = 900  # longest side of an embedded map (larger rasters are block-averaged)
_DISPLAY = 760  # longest side of a map on the page (CSS px)
_AZIMUTH, _ALTITUDE = 315.0, 45.0
_HIST_BINS = 71


def _get(d: Any, *keys: str, default: Any = None) -> Any:
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}"
    if isinstance(v, (float, np.floating)):
        return "–" if not math.isfinite(float(v)) else f"{float(v):,.{digits}f}"
    return html.escape(str(v))


def _table(header: list[str], rows: list[list[Any]], first_left: bool = True) -> str:
    th = "".join(f"<th{' class=l' if i == 0 and first_left else ''}>{html.escape(h)}</th>"
                 for i, h in enumerate(header))
    body = "".join(
        "<tr>" + "".join(f"<td{' class=l' if i == 0 and first_left else ''}>{c}</td>"
                         for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _no_data(title: str) -> str:
    return f"<p class=note>{html.escape(title)}: no data</p>"


def _positive(v: Any) -> float | None:
    """``v`` as a finite positive float, else None."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) and f > 0 else None


def _float_2d(a: Any) -> np.ndarray | None:
    """A 2-D floating view/copy of ``a`` with at least one finite value, else None."""
    if a is None:
        return None
    a = np.asarray(a)
    if a.ndim != 2 or a.size == 0:
        return None
    a = a if a.dtype.kind == "f" else a.astype(float)
    return a if np.isfinite(a).any() else None


def _like(a: Any, ref: np.ndarray) -> np.ndarray | None:
    """``a`` as an array if it has the shape of ``ref``, else None."""
    return np.asarray(a) if a is not None and np.shape(a) == ref.shape else None


# ---------------------------------------------------------------- numbers and ticks


def _nice_length(span: float) -> float:
    """The largest 1/2/5 x 10^n not longer than a quarter of ``span``."""
    raw = span / 4
    base = 10 ** math.floor(math.log10(raw))
    return max(m * base for m in (1, 2, 5) if m * base <= raw)


def _ticks(lo: float, hi: float, n: int = 5) -> tuple[list[float], float]:
    """About ``n`` round tick values in [lo, hi] and their step."""
    raw = (hi - lo) / n
    base = 10 ** math.floor(math.log10(raw))
    step = next(m * base for m in (1, 2, 5, 10) if m * base >= raw * 0.999)
    first = math.ceil(lo / step - 1e-9)
    return [i * step for i in range(first, math.floor(hi / step + 1e-9) + 1)], step


def _tick_label(v: float, step: float) -> str:
    digits = max(0, -math.floor(math.log10(step) + 1e-9))
    s = f"{v:.{digits}f}"
    return "0" if float(s) == 0 else s.replace("-", "−")


def _metres(length: float) -> str:
    return f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"


def _count_label(c: float) -> str:
    for div, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if c >= div:
            return f"{c / div:g}{unit}"
    return f"{c:g}"


def _sym_limit(a: np.ndarray) -> float:
    """Symmetric colour limit: the 99th percentile of |a| (1 when degenerate)."""
    v = np.abs(a[np.isfinite(a)])
    lim = float(np.percentile(v, 99)) if v.size else 1.0
    return lim if lim > 0 else (float(v.max()) if v.size and v.max() > 0 else 1.0)


# ---------------------------------------------------------------- rasters -> RGBA -> PNG


def _factors(shape: tuple[int, ...]) -> tuple[int, int]:
    """(k, f): block-average by k to at most _MAX_PX, or repeat small rasters f times towards _DISPLAY."""
    long = max(shape)
    if long > _MAX_PX:
        return math.ceil(long / _MAX_PX), 1
    return 1, max(1, _DISPLAY // long)


def _fold(a: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Sums of k consecutive entries along ``axis`` (0 or 1; the last group may be shorter)."""
    shape = list(a.shape)
    shape[axis] = -(-shape[axis] // k)
    out = np.zeros(shape, np.float64 if a.dtype.kind == "f" else np.int32)
    for i in range(k):
        x = a[i::k] if axis == 0 else a[:, i::k]
        if axis == 0:
            out[: x.shape[0]] += x
        else:
            out[:, : x.shape[1]] += x
    return out


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """NaN-aware mean over k x k blocks (partial blocks at the edges); NaN where a block has no data."""
    if k <= 1:
        return a
    ok = np.isfinite(a)
    total = _fold(_fold(np.where(ok, a, 0.0), k, 0), k, 1)
    count = _fold(_fold(ok, k, 0), k, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _block_any(m: np.ndarray, k: int) -> np.ndarray:
    m = np.asarray(m, bool)
    return m if k <= 1 else _fold(_fold(m, k, 0), k, 1) > 0


def _repeat(a: np.ndarray, f: int) -> np.ndarray:
    return a if f <= 1 else np.repeat(np.repeat(a, f, axis=0), f, axis=1)


def colour_ramp(values: np.ndarray, limit: float, table: np.ndarray = RDBU) -> np.ndarray:
    """RGBA uint8 of ``values`` on ``table`` spread evenly from -limit to +limit: 0 is the centre colour,
    ±limit and beyond the end colours, NaN transparent."""
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    limit = _positive(limit) or 1.0
    t = np.clip(np.where(ok, v, 0.0) / (2 * limit) + 0.5, 0.0, 1.0) * (len(table) - 1)
    knots = np.arange(len(table))
    out = np.empty(v.shape + (4,), np.uint8)
    for ch in range(3):
        out[..., ch] = np.rint(np.interp(t, knots, table[:, ch]))
    out[..., 3] = np.where(ok, 255, 0)
    return out


def hillshade(z: np.ndarray, cell: float, azimuth: float = _AZIMUTH, altitude: float = _ALTITUDE) -> np.ndarray:
    """Lambertian illumination in [0, 1] of the north-up surface ``z`` (sun azimuth clockwise from
    north); flat ground and cells without a gradient get sin(altitude)."""
    flat = math.sin(math.radians(altitude))
    if min(z.shape) < 2:
        return np.full(z.shape, flat)
    d_row, d_col = np.gradient(np.asarray(z, float), cell)
    dx, dy = d_col, -d_row  # rows run from north to south
    az, horiz = math.radians(azimuth), math.cos(math.radians(altitude))
    with np.errstate(invalid="ignore"):
        s = (flat - horiz * math.sin(az) * dx - horiz * math.cos(az) * dy) / np.sqrt(1 + dx * dx + dy * dy)
    return np.where(np.isfinite(s), np.clip(s, 0.0, 1.0), flat)


def _exaggeration(z: np.ndarray, cell: float, target: float = 0.5, cap: float = 5.0) -> float:
    """Vertical exaggeration (1 to ``cap``) bringing the 95th-percentile slope of gentle relief to ``target``."""
    if min(z.shape) < 2:
        return 1.0
    d_row, d_col = np.gradient(z, cell)
    g = np.hypot(d_row, d_col)
    g = g[np.isfinite(g)]
    p95 = float(np.percentile(g, 95)) if g.size else 0.0
    return min(max(target / p95, 1.0), cap) if p95 > 0 else 1.0


def _shade(rgba: np.ndarray, shade: np.ndarray, strength: float = 0.6) -> np.ndarray:
    """Darken/brighten the colours by the illumination; flat ground keeps its ramp colour."""
    gain = 1 + strength * (shade / math.sin(math.radians(_ALTITUDE)) - 1)
    out = rgba.copy()
    out[..., :3] = np.clip(rgba[..., :3] * gain[..., None], 0, 255)
    return out


def _outline(mask: np.ndarray) -> np.ndarray:
    """Cells of ``mask`` with a 4-neighbour outside it."""
    inner = mask.copy()
    inner[1:] &= mask[:-1]
    inner[:-1] &= mask[1:]
    inner[:, 1:] &= mask[:, :-1]
    inner[:, :-1] &= mask[:, 1:]
    return mask & ~inner


def png_bytes(rgba: np.ndarray) -> bytes:
    """An (h, w, 4) uint8 array as an 8-bit RGBA PNG (filter 0, fast zlib)."""
    h, w = rgba.shape[:2]
    raw = np.zeros((h, 1 + 4 * w), np.uint8)
    raw[:, 1:] = np.ascontiguousarray(rgba, np.uint8).reshape(h, 4 * w)

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1)) + chunk(b"IEND", b""))


def _png_uri(rgba: np.ndarray) -> str:
    return "data:image/png;base64," + base64.b64encode(png_bytes(rgba)).decode("ascii")


# ---------------------------------------------------------------- SVG decorations


def _halo(size: float) -> str:
    """SVG text attributes: ``size`` px with a white outline, readable over any background."""
    return f'font-size="{size}" paint-order="stroke" stroke="#fff" stroke-width="3" stroke-linejoin="round"'


def _scale_bar(width: float, height: float, span_m: float) -> str:
    """Bottom-left scale bar, half black half white, with a nice length in metres."""
    length = _nice_length(span_m)
    px, x, y = length / span_m * width, 14.0, height - 16.0
    box = max(px, 44.0) + 12
    return (f'<rect x="{x - 6}" y="{y - 22:.1f}" width="{box:.1f}" height="34" rx="3" fill="#fff" '
            f'fill-opacity=".75"/><rect x="{x}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#000"/>'
            f'<rect x="{x + px / 2:.1f}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#fff" '
            f'stroke="#000"/><text x="{x + px / 2:.1f}" y="{y - 5:.1f}" text-anchor="middle" '
            f'font-size="13">{_metres(length)}</text>')


def _north_arrow(width: float) -> str:
    return (f'<g transform="translate({width - 24:.1f},10)"><polygon points="0,0 9,26 0,19 -9,26" '
            f'fill="#000" stroke="#fff" stroke-width="1.5"/>'
            f'<text x="0" y="42" text-anchor="middle" font-weight="bold" {_halo(14)}>N</text></g>')


def _colour_bar(table: np.ndarray, limit: float, label: str, ident: str,
                ends: tuple[str, str] = ("", "")) -> str:
    """A horizontal SVG colour bar from -limit to +limit with ticks in metres."""
    w, x0, x1, y, h = 480, 30, 450, 4, 14
    stops = "".join(f'<stop offset="{i / (len(table) - 1):.3f}" stop-color="rgb({r:.0f},{g:.0f},{b:.0f})"/>'
                    for i, (r, g, b) in enumerate(table))
    ticks, step = _ticks(-limit, limit, 4)
    marks = "".join(
        f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{y + h}" y2="{y + h + 4}" stroke="#000"/>'
        f'<text x="{x:.1f}" y="{y + h + 16}" text-anchor="middle">{_tick_label(t, step)}</text>'
        for t in ticks for x in [x0 + (t + limit) / (2 * limit) * (x1 - x0)])
    end_text = (f'<text x="{x0}" y="54">{html.escape(ends[0])}</text>'
                f'<text x="{x1}" y="54" text-anchor="end">{html.escape(ends[1])}</text>')
    return (f'<svg class=plot id="{ident}-colour-bar" viewBox="0 0 {w} 60" width="{w}" height="60" '
            f'font-size="12" role="img" aria-label="{html.escape(label)}">'
            f'<defs><linearGradient id="{ident}-ramp">{stops}</linearGradient></defs>'
            f'<rect x="{x0}" y="{y}" width="{x1 - x0}" height="{h}" fill="url(#{ident}-ramp)" stroke="#666"/>'
            f'{marks}{end_text}<text x="{(x0 + x1) / 2}" y="54" text-anchor="middle">{html.escape(label)}</text>'
            "</svg>")


def _extent_text(grid: GridSpec, shape: tuple[int, int], k: int) -> str:
    u = grid.xy_unit or 1.0
    x0, y1 = grid.xmin / u, grid.ymax / u
    x1, y0 = x0 + shape[1] * grid.cell / u, y1 - shape[0] * grid.cell / u
    unit = "m" if u == 1 else "CRS units"
    shown = f", shown as {k} x {k} cell means" if k > 1 else ""
    return (f"Extent x {x0:,.1f} – {x1:,.1f}, y {y0:,.1f} – {y1:,.1f} ({unit}); "
            f"{shape[0]:,} x {shape[1]:,} cells of {grid.cell:g} m{shown}.")


def _map_figure(ident: str, title: str, rgba: np.ndarray, span_m: float, colour_bar: str, caption: str) -> str:
    """The PNG map with a scale bar and north arrow overlaid, its colour bar and caption."""
    h, w = rgba.shape[:2]
    s = _DISPLAY / max(h, w)
    wd, hd = round(w * s), round(h * s)
    overlay = (f'<svg viewBox="0 0 {wd} {hd}" font-family="sans-serif" aria-hidden="true">'
               f"{_scale_bar(wd, hd, span_m)}{_north_arrow(wd)}</svg>")
    return (f'<figure><div class=map style="width:{wd}px"><img id="{ident}" alt="{html.escape(title)}" '
            f'src="{_png_uri(rgba)}" width="{w}" height="{h}">{overlay}</div>{colour_bar}'
            f"<figcaption>{caption}</figcaption></figure>")


# ---------------------------------------------------------------- figures


def difference_map(diff: np.ndarray, grid: GridSpec, relief: np.ndarray | None = None,
                   filled_mask: np.ndarray | None = None, title: str = "DEM of difference",
                   ident: str = "difference-map") -> str | None:
    """HTML figure: ``diff`` on a diverging ramp centred on 0 (red cut, blue fill), hillshaded by
    ``relief`` (else by ``diff``), refilled cells outlined in black; None without data."""
    d = _float_2d(diff)
    if d is None:
        return None
    k, f = _factors(d.shape)
    shown = block_mean(d, k)
    lim = _sym_limit(shown)
    rel = _float_2d(_like(relief, d))
    z = block_mean(rel, k) if rel is not None else shown
    rgba = _shade(colour_ramp(shown, lim, RDBU), hillshade(z * _exaggeration(z, grid.cell * k), grid.cell * k))
    rgba = _repeat(rgba, f)
    mask = _like(filled_mask, d)
    if mask is not None and mask.any():
        rgba[_outline(_repeat(_block_any(mask, k), f))] = (0, 0, 0, 255)
    caption = (f"{html.escape(title)}: after − before, red = cut (lowered), blue = fill (raised), ramp "
               f"±{lim:.3g} m (99th percentile of |difference|; larger values in the end colours), "
               f"hillshaded{' by the after DEM' if rel is not None else ''}. "
               f"{'Black outline: refilled cells. ' if mask is not None and mask.any() else ''}"
               f"Hatched: no data. {_extent_text(grid, d.shape, k)}")
    bar = _colour_bar(RDBU, lim, "after − before (m)", ident, ("cut", "fill"))
    return _map_figure(ident, title, rgba, d.shape[1] * grid.cell, bar, caption)


def residual_map(residual: np.ndarray, grid: GridSpec, relief: np.ndarray | None = None,
                 ident: str = "residual-map") -> str | None:
    """HTML figure: stable-ground residuals (after correction) on a symmetric ramp, over a faint grey
    hillshade of ``relief`` for context; None without data."""
    r = _float_2d(residual)
    if r is None:
        return None
    k, f = _factors(r.shape)
    shown = block_mean(r, k)
    lim = _sym_limit(shown)
    rgba = colour_ramp(shown, lim, PUOR)
    rel = _float_2d(_like(relief, r))
    if rel is not None:
        rel = rel[::k, ::k]  # context only: a stride is enough
        grey = np.clip(205 + 45 * (hillshade(rel, grid.cell * k) / math.sin(math.radians(_ALTITUDE)) - 1), 0, 255)
        context = (rgba[..., 3] == 0) & np.isfinite(rel)
        rgba[context] = np.stack([grey[context]] * 3 + [np.full(grey[context].shape, 255.0)], axis=-1)
    caption = (f"Residuals on stable ground after the bias correction, ramp ±{lim:.3g} m (99th percentile "
               f"of |residual|). {'Grey relief: not stable ground. ' if rel is not None else ''}"
               f"Hatched: no data. {_extent_text(grid, r.shape, k)}")
    bar = _colour_bar(PUOR, lim, "residual on stable ground (m)", ident)
    return _map_figure(ident, "Stable-ground residuals", _repeat(rgba, f), r.shape[1] * grid.cell, bar, caption)


def _hist_limit(v: np.ndarray, lod: float | None) -> float:
    """Symmetric histogram range: the 0.5-99.5 percentiles (of a subsample), wide enough for ±1.5 LoD."""
    lo, hi = np.percentile(v[:: max(1, v.size // 250_000)], [0.5, 99.5])
    return max(abs(float(lo)), abs(float(hi)), 1.5 * (lod or 0.0), 1e-3)


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
    parts = [f'<line x1="{left}" x2="{left + pw}" y1="{sy(10 ** p):.1f}" y2="{sy(10 ** p):.1f}" stroke="#e4e4e4"/>'
             f'<text x="{left - 6}" y="{sy(10 ** p) + 4:.1f}" text-anchor="end">{_count_label(10 ** p)}</text>'
             for p in range(0, math.floor(y_hi) + 1)]
    parts += [f'<rect class=bar x="{sx(edges[i]):.2f}" y="{sy(c):.1f}" width="{pw / n:.2f}" '
              f'height="{top + ph - sy(c):.1f}" fill="rgb({r},{g},{b})" stroke="#555" stroke-width=".5"/>'
              for i, c in enumerate(counts.tolist()) if c > 0 for r, g, b in [fills[i, :3].tolist()]]
    if lod:
        parts += [f'<rect x="{sx(-lod):.1f}" y="{top}" width="{sx(lod) - sx(-lod):.1f}" height="{ph}" '
                  'fill="#f39c12" fill-opacity=".3"/>'] + [
            f'<line x1="{sx(x):.1f}" x2="{sx(x):.1f}" y1="{top}" y2="{top + ph}" stroke="#d35400" '
            'stroke-dasharray="4 3"/>' for x in (-lod, lod)]
    ticks, step = _ticks(-lim, lim, 8)
    parts += [f'<line x1="{sx(t):.1f}" x2="{sx(t):.1f}" y1="{top + ph}" y2="{top + ph + 5}" stroke="#000"/>'
              f'<text x="{sx(t):.1f}" y="{top + ph + 18}" text-anchor="middle">{_tick_label(t, step)}</text>'
              for t in ticks]
    parts.append(f'<line x1="{sx(0):.1f}" x2="{sx(0):.1f}" y1="{top}" y2="{top + ph}" stroke="#000" '
                 'stroke-width="1.2"/>'
                 f'<path d="M{left},{top}V{top + ph}H{left + pw}" fill="none" stroke="#000"/>'
                 f'<text x="{left + pw / 2}" y="{h - 8}" text-anchor="middle">after − before (m)</text>'
                 f'<text transform="translate(16,{top + ph / 2}) rotate(-90)" text-anchor="middle">'
                 "cells (log scale)</text>")
    if lod:
        parts.append(f'<rect x="{left + pw - 22}" y="{top + 8}" width="14" height="12" fill="#f39c12" '
                     f'fill-opacity=".5"/><text x="{left + pw - 28}" y="{top + 18}" text-anchor="end" '
                     f"{_halo(12)}>{html.escape(lod_label)}</text>")
    return (f'<svg class=plot id="{ident}" viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-size="12" '
            f'role="img"><title>Histogram of after − before differences</title>{"".join(parts)}</svg>')


def histogram(diff: np.ndarray, lod: float | None = None, confidence: float | None = None,
              ident: str = "histogram") -> str | None:
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
    caption = (f"{v.size:,} cells in {_HIST_BINS} bins of {2 * lim / _HIST_BINS:.3g} m over ±{lim:.3g} m "
               f"(0.5–99.5th percentiles){f'; {hidden:,} cells beyond not shown' if hidden else ''}. "
               + ("Shaded: level of detection." if lod else "No level of detection in the report."))
    return f"<figure>{_hist_svg(counts, lim, lod, label, ident)}<figcaption>{caption}</figcaption></figure>"


def _volume_rows(report: dict) -> list[list[str]]:
    unc = _get(report, "uncertainty_m3", default={}) or {}
    rows = []
    for label, key in (("compensated", "volume_m3"), ("uncompensated", "volume_uncompensated_m3"),
                       ("paper plane (d_i)", "volume_paper_plane_m3"),
                       ("thresholded (|d| ≥ LoD)", "volume_thresholded_m3")):
        v = _get(report, key)
        if not isinstance(v, dict):
            continue
        cells = [html.escape(label)]
        for k in ("net", "cut", "fill"):
            s = _fmt(v.get(k))
            if key == "volume_m3" and isinstance(unc.get(k), (int, float)):
                s += f" ± {_fmt(unc.get(k))}"
            cells.append(s)
        cells.append(_fmt(v.get("area_m2"), 1))
        rows.append(cells)
    return rows


def _registration(report: dict) -> str:
    reg = _get(report, "registration", default={}) or {}
    rows = []
    for stage in ("coarse", "fine"):
        s = reg.get(stage)
        if isinstance(s, dict):
            rows.append([stage, _fmt(s.get("method")), _fmt(s.get("fitness"), 4),
                         _fmt(s.get("rmse"), 4), _fmt(s.get("accepted")),
                         _fmt(s.get("seconds"), 2)])
    out = _table(["stage", "method", "fitness", "RMSE (m)", "accepted", "time (s)"], rows)
    t = reg.get("transform")
    if t is not None:
        m = np.asarray(t, float).reshape(4, 4)
        out += "<p>Transform (after → before, row-major):</p>" + _table(
            ["", "c1", "c2", "c3", "c4"],
            [[f"r{i + 1}"] + [f"{x:.6f}" for x in m[i]] for i in range(4)])
    return out


def _kv(d: dict | None, digits: int = 4) -> str:
    if not isinstance(d, dict) or not d:
        return "<p class=note>not available</p>"
    rows = [[html.escape(str(k)), _fmt(v, digits) if not isinstance(v, (list, dict))
             else html.escape(str(v))[:300]] for k, v in d.items()]
    return _table(["item", "value"], rows)


def _inputs(report: dict) -> str:
    rows = []
    for which in ("before", "after"):
        i = _get(report, "inputs", which)
        if isinstance(i, dict):
            rows.append([which, _fmt(i.get("path")), _fmt(i.get("points")), _fmt(i.get("crs"))])
    g = _get(report, "grid", default={}) or {}
    out = _table(["epoch", "file", "points", "CRS"], rows)
    out += _table(["cell (m)", "rows", "cols", "CRS", "compared area (m²)"],
                  [[_fmt(g.get("cell_m")), _fmt(g.get("rows")), _fmt(g.get("cols")),
                    _fmt(g.get("crs")), _fmt(g.get("compared_area_m2"), 1)]], first_left=False)
    return out


def _correction(report: dict) -> str:
    c = _get(report, "correction", default={}) or {}
    params = c.get("params") if isinstance(c.get("params"), dict) else {}
    resid = c.get("residuals") or params.get("residuals")
    out = f"<p>Method: <b>{_fmt(c.get('method') or params.get('method'))}</b></p>"
    if params.get("coefficients") is not None:
        terms = params.get("terms") or [f"c{i}" for i in range(len(params["coefficients"]))]
        out += _table(["term", "coefficient"], [[html.escape(str(t)), f"{v:.6g}"] for t, v in
                                                zip(terms, params["coefficients"], strict=False)])
    return out + "<p>Residuals on stable ground (m):</p>" + _kv(resid)


def _sections(report: dict, arrays: dict, grid: GridSpec) -> list[str]:
    diff = arrays.get("difference")
    lod = (_get(report, "uncertainty", "lod_m") or _get(report, "uncertainty_m3", "lod_m")
           or _get(report, "lod_m"))
    conf = _get(report, "uncertainty", "confidence") or _get(report, "uncertainty_m3", "confidence")
    relief = arrays.get("dem_after")
    figures = [
        ("Difference map", difference_map(diff, grid, relief, arrays.get("filled_mask"))),
        ("Histogram", histogram(diff, lod, conf)),
        ("Stable-ground residuals", residual_map(arrays.get("residual"), grid, relief)),
    ]
    out = ["<h2>Volumes (m³)</h2>" + _table(["", "net", "cut", "fill", "area (m²)"],
                                            _volume_rows(report))
           + "<p class=note>± = 95 % interval including spatially correlated error; cut and "
           "fill are positive, net = fill − cut.</p>"]
    out += [f"<h2>{t}</h2>{fig or _no_data(t)}" for t, fig in figures]
    out.append("<h2>Uncertainty</h2>" + _kv(_uncertainty_summary(report)))
    out.append("<h2>Bias correction</h2>" + _correction(report))
    out.append("<h2>Registration</h2>" + _registration(report))
    out.append("<h2>Inputs and grid</h2>" + _inputs(report))
    if isinstance(report.get("holes"), dict):
        out.append("<h2>Holes and refilled cells</h2>" + _kv(report["holes"], 2))
    out.append("<h2>Timings (s)</h2>" + _kv(report.get("timings_s"), 2))
    return out


def _uncertainty_summary(report: dict) -> dict | None:
    u = report.get("uncertainty") or report.get("uncertainty_m3")
    if not isinstance(u, dict):
        return None
    return {k: v for k, v in u.items() if not isinstance(v, (dict, list))}


def render_html(report: dict, arrays: dict, grid: GridSpec) -> str:
    """The report as one HTML string."""
    title = "Soil volume change report"
    sw = _get(report, "software", "version")
    head = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
            f"<style>{_CSS}</style></head><body><h1>{title}</h1>")
    if sw:
        head += f"<p class=note>soilvolume {_fmt(sw)}</p>"
    return head + "\n".join(_sections(report, arrays, grid)) + "</body></html>"


def write_html(report: dict, arrays: dict, grid: GridSpec, path: str | Path) -> Path:
    """Write report.html atomically; returns its path."""
    path = Path(path)
    text = render_html(report, arrays, grid)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
