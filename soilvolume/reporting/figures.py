"""report.html's maps, drawn in numpy without a plotting library: coloured and hillshaded PNGs with
colour bars, scale bars and north arrows as inline SVG."""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np
from markupsafe import Markup

from ..core.types import GridSpec
from .svgparts import DISPLAY, _repeat, block_any, block_mean, colour_bar, extent_text, map_figure


def ramp(colours: str) -> np.ndarray:
    """A colour table (n, 3) of floats from hex colours separated by spaces."""
    return np.array([list(bytes.fromhex(c)) for c in colours.split()], float)


# ColorBrewer 11-class ramps, low -> high (as matplotlib's RdBu / PuOr): red = cut, blue = fill.
RDBU = ramp("67001f b2182b d6604d f4a582 fddbc7 f7f7f7 d1e5f0 92c5de 4393c3 2166ac 053061")
PUOR = ramp("7f3b08 b35806 e08214 fdb863 fee0b6 f7f7f7 d8daeb b2abd2 8073ac 542788 2d004b")
_MAX_PX = 900  # longest side of an embedded map (larger rasters are block-averaged)
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


def _sym_limit(a: np.ndarray) -> float:
    """Symmetric colour limit: the 99th percentile of |a| (1 when degenerate)."""
    v = np.abs(a[np.isfinite(a)])
    lim = float(np.percentile(v, 99)) if v.size else 1.0
    return lim if lim > 0 else (float(v.max()) if v.size and v.max() > 0 else 1.0)


def _factors(shape: tuple[int, ...]) -> tuple[int, int]:
    """(k, f): block-average by k to at most _MAX_PX, or repeat small rasters f times towards DISPLAY."""
    long = max(shape)
    if long > _MAX_PX:
        return math.ceil(long / _MAX_PX), 1
    return 1, max(1, DISPLAY // long)


def colour_ramp(values: np.ndarray, limit: float, table: np.ndarray = RDBU) -> np.ndarray:
    """RGBA uint8 of ``values`` on ``table`` spread evenly from -limit to +limit: 0 is the centre colour,
    ±limit and beyond the end colours, NaN transparent."""
    v = np.asarray(values, float)
    ok = np.isfinite(v)
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


def difference_map(
    diff: np.ndarray,
    grid: GridSpec,
    relief: np.ndarray | None = None,
    filled_mask: np.ndarray | None = None,
    title: str = "DEM of difference",
    ident: str = "difference-map",
    change: np.ndarray | None = None,
) -> Markup | None:
    """HTML figure: ``diff`` red (cut) to blue (fill), hillshaded by ``relief`` (else ``diff``), refilled
    cells outlined black, the change areas (``change``) green; None without data."""
    d = _float_2d(diff)
    if d is None:
        return None
    k, f = _factors(d.shape)
    shown = block_mean(d, k)
    lim = _sym_limit(shown)
    rel = _float_2d(_like(relief, d))
    z = block_mean(rel, k) if rel is not None else shown
    shaded = hillshade(z * _exaggeration(z, grid.cell * k), grid.cell * k)
    rgba = _repeat(_shade(colour_ramp(shown, lim, RDBU), shaded), f)
    outlined = {
        "Black outline: refilled cells. ": (filled_mask, (0, 0, 0, 255)),
        "Green outline: the areas of significant change the headline cut and fill are summed over "
        "(polygons in change_areas.geojson). ": (change, (0, 150, 0, 255)),
    }
    said = ""
    for words, (marks, colour) in outlined.items():
        if (m := _like(marks, d)) is not None and m.any():  # outlined at display scale
            rgba[_outline(_repeat(block_any(m, k), f))] = colour
            said += words
    caption = (
        f"{html.escape(title)}: after − before, red = cut (lowered), blue = fill (raised), ramp "
        f"±{lim:.3g} m (99th percentile of |difference|; larger values in the end colours), "
        f"hillshaded{' by the after DEM' if rel is not None else ''}. "
        f"{said}Hatched: no data. {extent_text(grid, d.shape, k)}"
    )
    bar = colour_bar(RDBU, lim, "after − before (m)", ident, ("cut", "fill"))
    return map_figure(ident, title, rgba, d.shape[1] * grid.cell, bar, caption)


def residual_map(
    residual: np.ndarray, grid: GridSpec, relief: np.ndarray | None = None, ident: str = "residual-map"
) -> Markup | None:
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
        f"Hatched: no data. {extent_text(grid, r.shape, k)}"
    )
    bar = colour_bar(PUOR, lim, "residual on stable ground (m)", ident)
    return map_figure(ident, "Stable-ground residuals", _repeat(rgba, f), r.shape[1] * grid.cell, bar, caption)
