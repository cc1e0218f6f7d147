"""report.html's *What is not soil*: each epoch's point rule, what was left out or counted per class
and object, and the class raster (``excluded.tif``) mapped over the hillshaded after DEM."""

from __future__ import annotations

import html
from typing import Any

import numpy as np
from markupsafe import Markup

from ..core.types import GridSpec
from ..volumes.quality import sentence
from .figures import _factors, _float_2d, _like, _shade, hillshade
from .svgparts import _repeat, extent_text, map_figure
from .text import Table

# excluded.tif codes (volumes/nonsoil.CLASS_CODES) -> colour (as resources/styles/excluded.qml)
PALETTE = dict(enumerate((tuple(bytes.fromhex(c)) for c in "4daf4a 984ea3 999999 ff7f00 e41a1c a6d854".split()), 1))
NAMES = {
    1: "vegetation (not gridded)",
    2: "objects by classification (not gridded)",
    3: "noise, water, unclassified (not gridded)",
    4: "moved object (left out of the volumes)",
    5: "object in one survey only (counted)",
    6: "rough change, vegetation? (counted, in the interval)",
}


def classes_map(classes: Any, grid: GridSpec, relief: Any = None, ident: str = "excluded-map") -> Markup | None:
    """HTML figure of the class raster over the hillshaded ``relief``; None when every cell is soil."""
    c = np.asarray(classes) if classes is not None else None
    if c is None or c.ndim != 2 or not ((c > 0) & (c < 255)).any():
        return None
    k, f = _factors(c.shape)
    rel = _float_2d(_like(relief, c))
    z = np.where(c < 255, 0.0, np.nan) if rel is None else rel
    shown = c[::k, ::k]
    rgba = np.zeros((*shown.shape, 4), np.uint8)
    rgba[shown < 255] = (240, 240, 240, 255)
    for code, colour in PALETTE.items():
        rgba[shown == code] = (*colour, 255)
    rgba = _repeat(_shade(rgba, hillshade(z[::k, ::k], grid.cell * k)), f)
    legend = "".join(
        f'<span style="display:inline-block;width:1em;height:1em;background:rgb{PALETTE[k_]};'
        f'margin:0 .3em 0 .8em;vertical-align:middle"></span>{html.escape(n)}'
        for k_, n in NAMES.items()
        if (shown == k_).any()
    )
    caption = (
        "What is not soil (excluded.tif): cells whose points were mostly not soil, objects found by their shape "
        f"(walls, compact, on unchanged ground) and rough change. {extent_text(grid, c.shape, k)}"
    )
    return map_figure(ident, "What is not soil", rgba, c.shape[1] * grid.cell, f"<p>{legend}</p>", caption)


def _row(name: str, part: dict) -> list[str]:
    return [name, *(f"{part.get(k, 0.0):,.1f}" for k in ("net", "cut", "fill", "area_m2"))]


def _change_rows(ex: dict) -> list[list[str]]:
    """The apparent change of each class left out, the rough change, grass patches, moved objects."""
    rows = [_row(name, part) for name, part in (ex.get("classes") or {}).items()]
    for key, name in (("rough", "rough change (counted)"), ("grass_patches", "grass patches (left out)")):
        if isinstance(ex.get(key), dict):
            rows.append(_row(name, ex[key]))
    if m := ex.get("moved_objects"):
        rows.append(_row(f"moved objects ({'left out' if m.get('excluded') else 'counted'}, {m.get('count', 0)})", m))
    return rows


def _objects(ex: dict) -> Table | None:
    items = ((ex.get("moved_objects") or {}).get("items") or []) + ((ex.get("single_objects") or {}).get("items") or [])
    rows = [
        [("moved, " if i["moved"] else "one survey only, ") + i["kind"], f"{i['x']:.1f}", f"{i['y']:.1f}"]
        + [f"{i['area_m2']:.1f}", f"{i['height_m']:.2f}", f"{i['volume_m3']:.1f}"]
        for i in items
    ]
    return Table(["object", "x", "y", "area (m²)", "height (m)", "volume (m³)"], rows) if rows else None


def tables(report: dict) -> dict | None:
    """The ``excluded`` section of report.json for the page (None without one): ``rule`` [(epoch,
    rule)], the ``change`` and ``objects`` tables and its sentences (``words``)."""
    ex = report.get("excluded")
    if not isinstance(ex, dict) or not ex:
        return None
    return {
        "rule": [(e, str(r)) for e, r in (ex.get("rule") or {}).items()],
        "change": Table(["apparent change", "net (m³)", "cut (m³)", "fill (m³)", "area (m²)"], _change_rows(ex)),
        "objects": _objects(ex),
        "words": sentence(ex),
    }
