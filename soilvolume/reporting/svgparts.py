"""The pieces of report.html's figures: block averaging of large grids, PNG encoding with zlib (no
imaging library), round ticks and their labels, text with a halo, the scale bar, north arrow and
colour bar of a map, and a map's figure (its PNG embedded)."""

from __future__ import annotations

import base64
import html
import math
import struct
import zlib

import numpy as np
from markupsafe import Markup

from ..core.cells import block_sums
from ..core.types import GridSpec

DISPLAY = 760  # longest side of a map on the page (CSS px)


def block_any(mask: np.ndarray, k: int) -> np.ndarray:
    """Whether any cell of each k x k block (partial blocks at the edges) is set."""
    mask = np.asarray(mask, bool)
    return mask if k <= 1 else block_sums(mask, k) > 0


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """NaN-aware mean over k x k blocks (partial blocks at the edges); NaN where a block has no data."""
    if k <= 1:
        return a
    ok = np.isfinite(a)
    total = block_sums(np.where(ok, a, 0.0), k)
    count = block_sums(ok, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _repeat(a: np.ndarray, f: int) -> np.ndarray:
    return a if f <= 1 else np.repeat(np.repeat(a, f, axis=0), f, axis=1)


def png_bytes(rgba: np.ndarray) -> bytes:
    """An (h, w, 4) uint8 array as an 8-bit RGBA PNG: every row but the first filtered by the
    row above it ("Up", zeros where a repeated row repeats it), fast zlib."""
    h, w = rgba.shape[:2]
    rows = np.ascontiguousarray(rgba, np.uint8).reshape(h, 4 * w)
    raw = np.empty((h, 1 + 4 * w), np.uint8)
    raw[:, 0] = 2
    raw[0] = np.r_[np.uint8(0), rows[0]]
    np.subtract(rows[1:], rows[:-1], out=raw[1:, 1:])  # modulo 256, as PNG's filter

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1))
        + chunk(b"IEND", b"")
    )


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


def count_label(c: float) -> str:
    for div, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if c >= div:
            return f"{c / div:g}{unit}"
    return f"{c:g}"


def halo(size: float) -> str:
    """SVG text attributes: ``size`` px with a white outline, readable over any background."""
    return f'font-size="{size}" paint-order="stroke" stroke="#fff" stroke-width="3" stroke-linejoin="round"'


def scale_bar(width: float, height: float, span_m: float) -> str:
    """Bottom-left scale bar, half black half white, as long as the largest 1/2/5 x 10^n metres not
    longer than a quarter of the map's ``span_m``."""
    raw = span_m / 4
    base = 10 ** math.floor(math.log10(raw))
    length = max(m * base for m in (1, 2, 5) if m * base <= raw)
    label = f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"
    px, x, y = length / span_m * width, 14.0, height - 16.0
    box = max(px, 44.0) + 12
    return (
        f'<rect x="{x - 6}" y="{y - 22:.1f}" width="{box:.1f}" height="34" rx="3" fill="#fff" '
        f'fill-opacity=".75"/><rect x="{x}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#000"/>'
        f'<rect x="{x + px / 2:.1f}" y="{y:.1f}" width="{px / 2:.1f}" height="6" fill="#fff" '
        f'stroke="#000"/><text x="{x + px / 2:.1f}" y="{y - 5:.1f}" text-anchor="middle" '
        f'font-size="13">{label}</text>'
    )


def colour_bar(table: np.ndarray, limit: float, label: str, ident: str, ends: tuple[str, str] = ("", "")) -> str:
    """A horizontal SVG colour bar from -limit to +limit with ticks in metres."""
    w, x0, x1, y, h = 480, 30, 450, 4, 14
    stops = "".join(
        f'<stop offset="{i / (len(table) - 1):.3f}" stop-color="rgb({r:.0f},{g:.0f},{b:.0f})"/>'
        for i, (r, g, b) in enumerate(table)
    )
    ticks, step = round_ticks(-limit, limit, 4)
    marks = "".join(
        f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{y + h}" y2="{y + h + 4}" stroke="#000"/>'
        f'<text x="{x:.1f}" y="{y + h + 16}" text-anchor="middle">{tick_label(t, step)}</text>'
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


def map_figure(ident: str, title: str, rgba: np.ndarray, span_m: float, colour_bar: str, caption: str) -> Markup:
    """The PNG map with a scale bar and north arrow overlaid, its colour bar and caption (escaped here)."""
    h, w = rgba.shape[:2]
    s = DISPLAY / max(h, w)
    wd, hd = round(w * s), round(h * s)
    overlay = (
        f'<svg viewBox="0 0 {wd} {hd}" font-family="sans-serif" aria-hidden="true">'
        f'{scale_bar(wd, hd, span_m)}<g transform="translate({wd - 24:.1f},10)"><polygon '
        'points="0,0 9,26 0,19 -9,26" fill="#000" stroke="#fff" stroke-width="1.5"/>'
        f'<text x="0" y="42" text-anchor="middle" font-weight="bold" {halo(14)}>N</text></g></svg>'
    )
    png = base64.b64encode(png_bytes(rgba)).decode("ascii")
    return Markup(
        f'<figure><div class=map style="width:{wd}px"><img id="{ident}" alt="{html.escape(title)}" '
        f'src="data:image/png;base64,{png}" width="{w}" height="{h}">{overlay}</div>{colour_bar}'
        f"<figcaption>{caption}</figcaption></figure>"
    )
