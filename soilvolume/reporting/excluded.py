"""The report's section on what is not soil: each epoch's point rule, the volumes left out per
class, the moved objects and the objects in one survey only, and a map of the class raster
(``excluded.tif``) over the hillshaded after DEM."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from ..core.types import GridSpec
from .figures import _extent_text, _factors, _float_2d, _like, _map_figure, _repeat, _shade, hillshade

# excluded.tif codes (volumes/nonsoil.CLASS_CODES) -> colour (as resources/styles/excluded.qml)
PALETTE = {
    1: (77, 175, 74),
    2: (152, 78, 163),
    3: (153, 153, 153),
    4: (255, 127, 0),
    5: (228, 26, 28),
    6: (166, 216, 84),
}
NAMES = {
    1: "vegetation (not gridded)",
    2: "objects by classification (not gridded)",
    3: "noise, water, unclassified (not gridded)",
    4: "moved object (left out of the volumes)",
    5: "object in one survey only (counted)",
    6: "rough change, vegetation? (counted, in the interval)",
}


def classes_map(classes: Any, grid: GridSpec, relief: Any = None, ident: str = "excluded-map") -> str | None:
    """HTML figure of the class raster over the hillshaded ``relief``; None when every cell is soil."""
    c = np.asarray(classes) if classes is not None else None
    if c is None or c.ndim != 2 or not ((c > 0) & (c < 255)).any():
        return None
    k, f = _factors(c.shape)
    rel = _float_2d(_like(relief, c))
    z = np.where(c < 255, 0.0, np.nan) if rel is None else rel
    step = max(1, k)
    shown = c[::step, ::step]
    rgba = np.zeros((*shown.shape, 4), np.uint8)
    rgba[shown < 255] = (240, 240, 240, 255)
    for code, colour in PALETTE.items():
        rgba[shown == code] = (*colour, 255)
    rgba = _shade(rgba, hillshade(z[::step, ::step], grid.cell * step))
    rgba = _repeat(rgba, f)
    legend = "".join(
        f'<span style="display:inline-block;width:1em;height:1em;background:rgb{PALETTE[k_]};'
        f'margin:0 .3em 0 .8em;vertical-align:middle"></span>{html.escape(n)}'
        for k_, n in NAMES.items()
        if (shown == k_).any()
    )
    caption = (
        "What is not soil (excluded.tif): cells whose points were mostly not soil, objects found by their shape "
        f"(walls, compact, on unchanged ground) and rough change. {_extent_text(grid, c.shape, k)}"
    )
    return _map_figure(ident, "What is not soil", rgba, c.shape[1] * grid.cell, f"<p>{legend}</p>", caption)


def excluded_section(report: dict, table) -> str:
    """Tables of the ``excluded`` section of report.json (``table``: the report's table helper)."""
    from ..volumes.nonsoil import sentence

    ex = report.get("excluded")
    if not isinstance(ex, dict) or not ex:
        return "<p class=note>not available</p>"
    rule = ex.get("rule") or {}
    out = "".join(f"<p>{html.escape(e)}: {html.escape(str(r))}</p>" for e, r in rule.items())
    rows = []
    for name, part in (ex.get("classes") or {}).items():
        rows.append([html.escape(name), *(f"{part.get(k, 0.0):,.1f}" for k in ("net", "cut", "fill", "area_m2"))])
    for key, name in (("rough", "rough change (counted)"), ("grass_patches", "grass patches (left out)")):
        part = ex.get(key)
        if isinstance(part, dict):
            rows.append([html.escape(name), *(f"{part.get(k, 0.0):,.1f}" for k in ("net", "cut", "fill", "area_m2"))])
    m = ex.get("moved_objects") or {}
    if m:
        label = "moved objects (" + ("left out" if m.get("excluded") else "counted") + f", {m.get('count', 0)})"
        rows.append([html.escape(label), *(f"{m.get(k, 0.0):,.1f}" for k in ("net", "cut", "fill", "area_m2"))])
    out += table(["apparent change", "net (m³)", "cut (m³)", "fill (m³)", "area (m²)"], rows)
    items = (m.get("items") or []) + ((ex.get("single_objects") or {}).get("items") or [])
    if items:
        out += table(
            ["object", "x", "y", "area (m²)", "height (m)", "volume (m³)"],
            [
                [
                    html.escape(("moved, " if i["moved"] else "one survey only, ") + i["kind"]),
                    f"{i['x']:.1f}",
                    f"{i['y']:.1f}",
                    f"{i['area_m2']:.1f}",
                    f"{i['height_m']:.2f}",
                    f"{i['volume_m3']:.1f}",
                ]
                for i in items
            ],
        )
    words = sentence(ex)
    if words:
        out += "<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in words) + "</ul>"
    return out
