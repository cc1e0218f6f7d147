"""Change no survey could see: holes without any point in the works. From its rim, a pond reads the
water, not the pit's bottom (0.8 m of water: 82 % of a 2 m pit's cut). A basin mostly rimmed by change
is a range, from its rim's fill to the rim's slope carried inwards (at most :data:`DEEPER` times the
rim's depth), widening the interval; the verdict says why."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..results import Epochs
from .interpolate import FOUR, enclosed_holes, fill

RIM_SHARE = 0.5  # share of a hole's rim in change areas that makes it a hole in the works
DEEPER = 2.0  # the walls carried on into a hole go at most this many times the rim's depth further
MIN_M3 = 0.5  # ranges below this are noise, not named
PAD = 8  # cells around a hole's box that hold its rings and the ground they are compared with
BASIN_DROP_M = 0.2  # a hole whose rim lies this much below the ground around it (median): a basin


@dataclass(frozen=True)
class Blind:
    """The report's ``blind`` section and the bound (m3 per part) it adds to the interval."""

    report: dict
    bound: dict


def blind_change(
    diff: np.ndarray, epochs: Epochs, change: np.ndarray, cell_area: float, seen_once: np.ndarray
) -> Blind:
    """The basins without any point in the ``change`` areas and their range (see module), and the change counted on
    ``seen_once`` cells (filled in one survey from its own ground)."""
    bound = dict.fromkeys(("net", "cut", "fill"), 0.0)
    items = []
    for name, e in zip(("after", "before"), epochs, strict=True):
        empty = (e.counts + e.nonsoil()) == 0
        labels, _ = ndimage.label(enclosed_holes(~empty, empty.size), FOUR)
        for k, box in enumerate(ndimage.find_objects(labels), 1):
            win = tuple(slice(max(b.start - PAD, 0), b.stop + PAD) for b in box)  # the hole and its rings
            cells = labels[win] == k
            item = _hole(diff[win], cells, change[win], cell_area) if _basin(e.heights[win], cells) else None
            if item is None:
                continue
            reach = max(abs(v) for v in item["range_m3"])
            bound["cut" if item["rim_difference_m"] < 0 else "fill"] += reach
            bound["net"] += reach
            items.append({**item, "survey": name})
    report = {"count": len(items), "area_m2": sum(i["area_m2"] for i in items), "bound_m3": bound, "items": items}
    once = change & seen_once
    d = np.where(once, np.nan_to_num(diff), 0.0)
    cut, fill = float(-d[d < 0].sum()) * cell_area, float(d[d > 0].sum()) * cell_area
    report["interpolated"] = {"area_m2": float(once.sum()) * cell_area, "cut": cut, "fill": fill}
    return Blind(report, bound)


def _rings(cells: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(near, far): a hole's ``valid`` cells next to it, and those 3 to 4 cells out."""
    near = ndimage.binary_dilation(cells) & ~cells & valid
    far = ndimage.binary_dilation(cells, iterations=4) & ~ndimage.binary_dilation(cells, iterations=2) & valid
    return near, far


def _basin(h: np.ndarray, cells: np.ndarray) -> bool:
    """Whether the hole's rim lies (median) :data:`BASIN_DROP_M` below the ground a few cells out: a
    pond or a pit's bottom, not an occlusion beside or on a pile (whose refill stands)."""
    near, far = _rings(cells, np.isfinite(h))
    if near.sum() < 4 or not far.any():
        return False
    total = ndimage.uniform_filter(np.where(far, h, 0.0), 7, mode="constant")
    count = ndimage.uniform_filter(far.astype(float), 7, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        around = np.where(count > 0, total / count, np.nan)  # the ground a few cells out, on average
    drop = (around - h)[near]
    return bool(np.nanmedian(drop) >= BASIN_DROP_M) if np.isfinite(drop).any() else False


def _hole(diff: np.ndarray, cells: np.ndarray, change: np.ndarray, cell_area: float) -> dict | None:
    """One hole's range (m3, against the headline), or None off the works or when negligible."""
    ring = ndimage.binary_dilation(cells, iterations=2) & ~cells & np.isfinite(diff)
    if not ring.any() or float(np.mean(change[ring])) < RIM_SHARE:
        return None
    near, far = _rings(cells, np.isfinite(diff))
    d_near = float(np.median(diff[near])) if near.any() else 0.0
    d_far = float(np.median(diff[far])) if far.any() else d_near
    step = (d_near - d_far) / 2.5  # per cell, going in
    if step * d_near <= 0:  # the rim does not deepen inwards: nothing to carry on
        step = 0.0
    dist = ndimage.distance_transform_edt(cells)
    extra = np.clip(step * dist, -DEEPER * abs(d_near), DEEPER * abs(d_near))[cells]
    extra_m3 = float(extra.sum()) * cell_area
    shown = np.isfinite(diff[cells])
    rim_fill = fill(np.where(cells, np.nan, diff), cells, "harmonic")[cells]
    left_out = float(np.nansum(np.where(shown, 0.0, rim_fill))) * cell_area  # not in the headline
    rng = (left_out, left_out + extra_m3)
    if max(abs(rng[0]), abs(rng[1])) < MIN_M3:
        return None
    return {
        "area_m2": float(cells.sum()) * cell_area,
        "rim_difference_m": d_near,
        "walls_m3": extra_m3,
        "range_m3": [float(rng[0]), float(rng[1])],
        "in_headline": bool(shown.all()),
    }
