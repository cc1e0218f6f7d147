"""report.html's note when the headline's cut (or fill) reads 0 while the map shows such cells: which
rule of the change areas (:mod:`soilvolume.volumes.change`) left how many out, which sum to trust."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..volumes.change import BUFFER_CELLS, MIN_CELLS

ZERO = 0.005  # m³: what "0.00" shows


def zero_notes(
    report: dict, arrays: dict | None, words: tuple[str, str, str] = ("", "cut", "fill")
) -> list[tuple[str, str]]:
    """(word, why) per headline kind (cut, fill) that reads 0 while the compared cells hold some of
    that kind; none when none does. ``words``: the headline's (lead, cut, fill) words."""
    volumes = report.get("volume_m3") or {}
    every = report.get("volume_all_cells_m3") or {}
    lod = (report.get("uncertainty_m3") or {}).get("lod_m")
    out = []
    for kind, sign, word in (("cut", -1.0, words[1]), ("fill", 1.0, words[2])):
        shown, anywhere = volumes.get(kind), every.get(kind)
        if not _number(shown) or abs(shown) >= ZERO or not _number(anywhere) or anywhere < ZERO:
            continue
        cells = _left_out((arrays or {}).get("difference"), (arrays or {}).get("change"), sign, lod)
        out.append((word, _why(report, kind, sign, cells)))
    return out


def _why(report: dict, kind: str, sign: float, cells: dict[str, Any] | None) -> str:
    lod = (report.get("uncertainty_m3") or {}).get("lod_m")
    beyond = "lower" if sign < 0 else "higher"
    threshold = f"{sign * lod:+.2f} m" if _number(lod) else "their level of detection"
    text = (
        f"the headline counts only areas of significant change: at least {MIN_CELLS} touching measured cells "
        f"{beyond} than their level of detection ({_m(lod)} on stable ground, more in a cell with few points or "
        f"a wide spread of heights), with a rim of {BUFFER_CELLS} cell; cells on the border of the compared area, "
        "only partly covered by a survey, never start one. "
    )
    if cells is not None and cells["count"]:
        parts = [
            f"{cells['border']} on the border",
            f"{cells['small']} in patches of fewer than {MIN_CELLS} such cells",
        ]
        parts += [f"{cells['raised']} within their own cell's higher level of detection"] if cells["raised"] else []
        text += (
            f"{cells['count']} cell{'s' if cells['count'] != 1 else ''} {'are' if cells['count'] != 1 else 'is'} "
            f"{beyond} than {threshold} (down to {cells['extreme']:+.2f} m on the map): " + ", ".join(parts) + ". "
        )
    elif cells is not None:
        text += f"No cell is {beyond} than {threshold} (the most: {cells['extreme']:+.2f} m): all of it is noise. "
    return text + _sums(report, kind)


def _sums(report: dict, kind: str) -> str:
    """Where the left-out change shows in the report's other sums, and which number to trust."""
    thresholded = (report.get("volume_thresholded_m3") or {}).get(kind)
    every = (report.get("volume_all_cells_m3") or {}).get(kind)
    unc = report.get("uncertainty_m3") or {}
    net, net_all = (report.get("volume_m3") or {}).get("net"), (report.get("volume_all_cells_m3") or {}).get("net")
    text = "Such cells count as survey noise"
    if _number(thresholded):
        text += f": {thresholded:,.2f} m³ if every cell beyond the level of detection were counted"
    text += f"; summed over every compared cell, noise included (the paper's sum), {kind} is {every:,.2f} m³. "
    if _number(net) and _number(net_all):
        text += (
            f"Trust the headline (net {net:+,.2f}{_pm(unc.get('net'))} m³): the every-cell net "
            f"({net_all:+,.2f}{_pm(unc.get('net_all_cells'))} m³) adds the noise and its wider interval."
        )
    return text


def _left_out(diff: Any, change: Any, sign: float, lod: Any) -> dict[str, Any] | None:
    """The cells of ``sign`` beyond the stable-ground LoD outside the change areas: how many, on
    the border of the compared area, in patches under MIN_CELLS, else (raised own LoD)."""
    from scipy import ndimage

    d = np.asarray(diff, dtype=float) if diff is not None else None
    if d is None or d.ndim != 2 or not _number(lod) or not np.isfinite(d).any():
        return None
    valid = np.isfinite(d)
    areas = np.asarray(change, dtype=bool) if change is not None and np.shape(change) == d.shape else False
    beyond = valid & (sign * np.where(valid, d, 0.0) > lod) & ~areas
    border = valid & ~ndimage.binary_erosion(valid, border_value=0)
    inner = beyond & ~border
    labels, n = ndimage.label(inner, structure=np.ones((3, 3), bool))
    small = np.isin(labels, 1 + np.flatnonzero(np.bincount(labels.ravel(), minlength=n + 1)[1:] < MIN_CELLS))
    extreme = float(np.nanmin(d) if sign < 0 else np.nanmax(d))
    count, on_border, in_small = int(beyond.sum()), int((beyond & border).sum()), int((inner & small).sum())
    raised = count - on_border - in_small
    return {"count": count, "border": on_border, "small": in_small, "raised": raised, "extreme": extreme}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def _m(value: Any) -> str:
    return f"{value:.2f} m" if _number(value) else "its level"


def _pm(value: Any) -> str:
    return f" ± {value:,.2f}" if _number(value) else ""
