"""Figures of report.html, drawn in numpy without a plotting library: maps as embedded PNGs
(coloured and hillshaded, encoded with zlib) with colour bars, scale bars and north arrows as
inline SVG, and the histogram of the difference as inline SVG."""

from __future__ import annotations

import base64
import html
import math
from typing import Any

import numpy as np

from ..core.types import GridSpec
from .raster import _block_any, _repeat, block_mean, png_bytes

# ColorBrewer 11-class ramps, low -> high (as matplotlib's RdBu / PuOr): red = cut, blue = fill.
RDBU = np.array(
    [
        [103, 0, 31],
        [178, 24, 43],
        [214, 96, 77],
        [244, 165, 130],
        [253, 219, 199],
        [247, 247, 247],
        [209, 229, 240],
        [146, 197, 222],
        [67, 147, 195],
        [33, 102, 172],
        [5, 48, 97],
    ],
    float,
)
PUOR = np.array(
    [
        [127, 59, 8],
        [179, 88, 6],
        [224, 130, 20],
        [253, 184, 99],
        [254, 224, 182],
        [247, 247, 247],
        [216, 218, 235],
        [178, 171, 210],
        [128, 115, 172],
        [84, 39, 136],
        [45, 0, 75],
    ],
    float,
)
_MAX_PX = 900  # longest side of an embedded map (larger rasters are block-averaged)
_DISPLAY = 760  # longest side of a map on the page (CSS px)
_AZIMUTH, _ALTITUDE = 315.0, 45.0


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
    return (
        f'<rect x="{x - 6}" y="{y - 22:.1f}" width="{box:.1f}" height="34" rx="3" fill="#fff" '
        f'fill-opacity=".75"/><rect x="{x}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#000"/>'
        f'<rect x="{x + px / 2:.1f}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#fff" '
        f'stroke="#000"/><text x="{x + px / 2:.1f}" y="{y - 5:.1f}" text-anchor="middle" '
        f'font-size="13">{_metres(length)}</text>'
    )


def _north_arrow(width: float) -> str:
    return (
        f'<g transform="translate({width - 24:.1f},10)"><polygon points="0,0 9,26 0,19 -9,26" '
        f'fill="#000" stroke="#fff" stroke-width="1.5"/>'
        f'<text x="0" y="42" text-anchor="middle" font-weight="bold" {_halo(14)}>N</text></g>'
    )


def _colour_bar(table: np.ndarray, limit: float, label: str, ident: str, ends: tuple[str, str] = ("", "")) -> str:
    """A horizontal SVG colour bar from -limit to +limit with ticks in metres."""
    w, x0, x1, y, h = 480, 30, 450, 4, 14
    stops = "".join(
        f'<stop offset="{i / (len(table) - 1):.3f}" stop-color="rgb({r:.0f},{g:.0f},{b:.0f})"/>'
        for i, (r, g, b) in enumerate(table)
    )
    ticks, step = _ticks(-limit, limit, 4)
    marks = "".join(
        f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{y + h}" y2="{y + h + 4}" stroke="#000"/>'
        f'<text x="{x:.1f}" y="{y + h + 16}" text-anchor="middle">{_tick_label(t, step)}</text>'
        for t in ticks
        for x in [x0 + (t + limit) / (2 * limit) * (x1 - x0)]
    )
    end_text = (
        f'<text x="{x0}" y="54">{html.escape(ends[0])}</text>'
        f'<text x="{x1}" y="54" text-anchor="end">{html.escape(ends[1])}</text>'
    )
    return (
        f'<svg class=plot id="{ident}-colour-bar" viewBox="0 0 {w} 60" width="{w}" height="60" '
        f'font-size="12" role="img" aria-label="{html.escape(label)}">'
        f'<defs><linearGradient id="{ident}-ramp">{stops}</linearGradient></defs>'
        f'<rect x="{x0}" y="{y}" width="{x1 - x0}" height="{h}" fill="url(#{ident}-ramp)" stroke="#666"/>'
        f'{marks}{end_text}<text x="{(x0 + x1) / 2}" y="54" text-anchor="middle">{html.escape(label)}</text>'
        "</svg>"
    )


def _extent_text(grid: GridSpec, shape: tuple[int, int], k: int) -> str:
    u = grid.xy_unit or 1.0
    x0, y1 = grid.xmin / u, grid.ymax / u
    x1, y0 = x0 + shape[1] * grid.cell / u, y1 - shape[0] * grid.cell / u
    unit = "m" if u == 1 else "CRS units"
    shown = f", shown as {k} x {k} cell means" if k > 1 else ""
    return (
        f"Extent x {x0:,.1f} – {x1:,.1f}, y {y0:,.1f} – {y1:,.1f} ({unit}); "
        f"{shape[0]:,} x {shape[1]:,} cells of {grid.cell:g} m{shown}."
    )


def _map_figure(ident: str, title: str, rgba: np.ndarray, span_m: float, colour_bar: str, caption: str) -> str:
    """The PNG map with a scale bar and north arrow overlaid, its colour bar and caption."""
    h, w = rgba.shape[:2]
    s = _DISPLAY / max(h, w)
    wd, hd = round(w * s), round(h * s)
    overlay = (
        f'<svg viewBox="0 0 {wd} {hd}" font-family="sans-serif" aria-hidden="true">'
        f"{_scale_bar(wd, hd, span_m)}{_north_arrow(wd)}</svg>"
    )
    return (
        f'<figure><div class=map style="width:{wd}px"><img id="{ident}" alt="{html.escape(title)}" '
        f'src="{_png_uri(rgba)}" width="{w}" height="{h}">{overlay}</div>{colour_bar}'
        f"<figcaption>{caption}</figcaption></figure>"
    )


# ---------------------------------------------------------------- figures


CHANGE_OUTLINE = (0, 150, 0, 255)
CHANGE_CAPTION = (
    "Green outline: the areas of significant change the headline cut and fill are summed over "
    "(polygons in change_areas.geojson). "
)


def difference_map(
    diff: np.ndarray,
    grid: GridSpec,
    relief: np.ndarray | None = None,
    filled_mask: np.ndarray | None = None,
    title: str = "DEM of difference",
    ident: str = "difference-map",
    change: np.ndarray | None = None,
) -> str | None:
    """HTML figure: ``diff`` on a diverging ramp centred on 0 (red cut, blue fill), hillshaded by
    ``relief`` (else by ``diff``), refilled cells outlined in black, the areas of significant
    change (``change``: the headline's cells) outlined in green; None without data."""
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
    areas = _like(change, d)
    if areas is not None and areas.any():
        rgba[_outline(_repeat(_block_any(areas, k), f))] = CHANGE_OUTLINE
    caption = (
        f"{html.escape(title)}: after − before, red = cut (lowered), blue = fill (raised), ramp "
        f"±{lim:.3g} m (99th percentile of |difference|; larger values in the end colours), "
        f"hillshaded{' by the after DEM' if rel is not None else ''}. "
        f"{'Black outline: refilled cells. ' if mask is not None and mask.any() else ''}"
        f"{CHANGE_CAPTION if areas is not None and areas.any() else ''}"
        f"Hatched: no data. {_extent_text(grid, d.shape, k)}"
    )
    bar = _colour_bar(RDBU, lim, "after − before (m)", ident, ("cut", "fill"))
    return _map_figure(ident, title, rgba, d.shape[1] * grid.cell, bar, caption)


def residual_map(
    residual: np.ndarray, grid: GridSpec, relief: np.ndarray | None = None, ident: str = "residual-map"
) -> str | None:
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
    caption = (
        f"Residuals on stable ground after the bias correction, ramp ±{lim:.3g} m (99th percentile "
        f"of |residual|). {'Grey relief: not stable ground. ' if rel is not None else ''}"
        f"Hatched: no data. {_extent_text(grid, r.shape, k)}"
    )
    bar = _colour_bar(PUOR, lim, "residual on stable ground (m)", ident)
    return _map_figure(ident, "Stable-ground residuals", _repeat(rgba, f), r.shape[1] * grid.cell, bar, caption)
