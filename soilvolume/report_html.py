"""A self-contained report.html: maps and histogram as embedded PNGs (matplotlib Agg), tables of
volumes, uncertainty, registration, inputs and timings. No network access, tolerant of missing
report keys."""

from __future__ import annotations

import base64
import html
import io
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .types import GridSpec

_CSS = """body{font-family:sans-serif;margin:1.5em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.2em}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}img{max-width:100%;display:block}
h2{border-bottom:1px solid #ccc;margin-top:1.5em}.note{color:#666;font-size:90%}"""


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


def _axes(width: float, height: float):
    """A pyplot-free Agg figure (safe inside QGIS, whatever backend pyplot uses) and its axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(uri: str | None, ident: str, alt: str) -> str:
    if uri is None:
        return f"<p class=note>{html.escape(alt)}: no data</p>"
    return f'<img id="{ident}" alt="{html.escape(alt)}" src="{uri}">'


def _extent(grid: GridSpec) -> tuple[float, float, float, float]:
    return (grid.xmin, grid.xmin + grid.cols * grid.cell, grid.ymax - grid.rows * grid.cell,
            grid.ymax)


def _nice_length(span: float) -> float:
    raw = span / 5
    base = 10 ** math.floor(math.log10(raw))
    return max(m * base for m in (1, 2, 5) if m * base <= raw)


def _decorate(ax, grid: GridSpec) -> None:
    """Scale bar (bottom left) and north arrow (top right) in axes coordinates."""
    x0, x1, y0, y1 = _extent(grid)
    length = _nice_length(x1 - x0)
    bx, by = x0 + 0.05 * (x1 - x0), y0 + 0.05 * (y1 - y0)
    ax.plot([bx, bx + length], [by, by], color="k", lw=4, solid_capstyle="butt")
    ax.text(bx + length / 2, by + 0.02 * (y1 - y0), f"{length:g} m", ha="center", va="bottom",
            fontsize=9, bbox={"fc": "white", "ec": "none", "alpha": 0.7, "pad": 1})
    ax.annotate("N", xy=(0.94, 0.95), xytext=(0.94, 0.83), xycoords="axes fraction",
                ha="center", va="center", fontsize=11, fontweight="bold",
                arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.5})
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)


def _sym_limit(a: np.ndarray) -> float:
    v = np.abs(a[np.isfinite(a)])
    lim = float(np.percentile(v, 99)) if v.size else 1.0
    return lim if lim > 0 else 1.0


def _hillshade(z: np.ndarray, cell: float) -> np.ndarray:
    from matplotlib.colors import LightSource

    filled = np.where(np.isfinite(z), z, np.nanmean(z) if np.isfinite(z).any() else 0.0)
    return LightSource(azdeg=315, altdeg=45).hillshade(filled, dx=cell, dy=cell)


def difference_map(diff: np.ndarray, grid: GridSpec, relief: np.ndarray | None = None,
                   filled_mask: np.ndarray | None = None, title: str = "DEM of difference"):
    """Hillshaded map of ``diff`` with a diverging ramp centred on 0 (red cut, blue fill)."""
    from matplotlib.colors import TwoSlopeNorm

    if not np.isfinite(diff).any():
        return None
    fig, ax = _axes(8, 8 * grid.rows / max(grid.cols, 1) + 0.5)
    ext = _extent(grid)
    shade = _hillshade(relief if relief is not None else diff, grid.cell)
    ax.imshow(np.where(np.isfinite(diff), shade, np.nan), cmap="gray", extent=ext,
              interpolation="nearest")
    lim = _sym_limit(diff)
    im = ax.imshow(diff, cmap="RdBu", norm=TwoSlopeNorm(0.0, -lim, lim), alpha=0.75, extent=ext,
                   interpolation="nearest")
    if filled_mask is not None and filled_mask.any():
        ax.contour(filled_mask.astype(float), levels=[0.5], colors="k", linewidths=0.5,
                   extent=ext, origin="upper")
    fig.colorbar(im, ax=ax, shrink=0.7, label="after − before (m)")
    ax.set_title(title)
    _decorate(ax, grid)
    return _png(fig)


def residual_map(residual: np.ndarray, grid: GridSpec):
    """Stable-ground residuals (after correction) with a symmetric ramp."""
    if residual is None or not np.isfinite(residual).any():
        return None
    fig, ax = _axes(7, 7 * grid.rows / max(grid.cols, 1) + 0.5)
    lim = _sym_limit(residual)
    im = ax.imshow(residual, cmap="PuOr", vmin=-lim, vmax=lim, extent=_extent(grid),
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.7, label="residual on stable ground (m)")
    ax.set_title("Stable-ground residuals")
    _decorate(ax, grid)
    return _png(fig)


def histogram(diff: np.ndarray, lod: float | None):
    """Histogram of the differences with the ±LoD band shaded."""
    v = diff[np.isfinite(diff)]
    if v.size == 0:
        return None
    fig, ax = _axes(8, 3.5)
    lo, hi = np.percentile(v, [0.1, 99.9])
    lim = max(abs(lo), abs(hi), (lod or 0) * 3, 1e-3)
    ax.hist(np.clip(v, -lim, lim), bins=121, range=(-lim, lim), color="#4a7fb5")
    if lod:
        ax.axvspan(-lod, lod, color="orange", alpha=0.3, label=f"±LoD95 = {lod:.3f} m")
        ax.legend(loc="upper right")
    ax.set_yscale("log")
    ax.set_xlabel("after − before (m)")
    ax.set_ylabel("cells")
    ax.set_title("Histogram of differences")
    return _png(fig)


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
    maps = [
        ("Difference map", difference_map(diff, grid, arrays.get("dem_after"),
                                          arrays.get("filled_mask"))
         if diff is not None else None, "difference-map"),
        ("Histogram", histogram(diff, lod) if diff is not None else None, "histogram"),
        ("Stable-ground residuals", residual_map(arrays.get("residual"), grid), "residual-map"),
    ]
    out = ["<h2>Volumes (m³)</h2>" + _table(["", "net", "cut", "fill", "area (m²)"],
                                            _volume_rows(report))
           + "<p class=note>± = 95 % interval including spatially correlated error; cut and "
           "fill are positive, net = fill − cut.</p>"]
    out += [f"<h2>{t}</h2>{_img(uri, ident, t)}" for t, uri, ident in maps]
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
