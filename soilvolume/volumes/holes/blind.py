"""Change no survey could see: holes with no point at all (water, a shadow, no returns) inside
the works.

A hole of one survey is refilled from its rim (small ones) or left out (large ones). On
unchanged ground that is right; inside a pit it is not: the rim of a pond is its water line, and
a surface interpolated from it is the water's, not the pit's bottom (a 2 m pit with 0.8 m of
water read 82 % of its cut). The ground under such a hole is unknown, so the volume there is a
range, not a number:

* at one end, the difference interpolated from the rim (what the headline holds for a refilled
  hole; for one left out, its volume is added to the range);
* at the other, the difference carried on into the hole at the rim's own slope (a pit's walls
  going on down, capped at :data:`DEEPER` times the depth seen at the rim).

The interval is widened by that range (it holds both readings) and the verdict says why. A hole
counts when most of its rim is in a change area and the survey's ground falls into it from all
around (a basin: water gathers there; an occlusion beside or on a pile has no such rim, and the
refill from it stands); holes on unchanged ground are not change.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy

from ...dem.grid import EpochDEM
from .interpolate import FOUR, enclosed_holes, fill

RIM_SHARE = 0.5  # share of a hole's rim in change areas that makes it a hole in the works
DEEPER = 2.0  # the walls carried on into a hole go at most this many times the rim's depth further
MIN_M3 = 0.5  # ranges below this are noise, not named
NAMES = ("after", "before")
PAD = 8  # cells around a hole's box that hold its rings and the ground they are compared with
BASIN_DROP_M = 0.2  # a hole whose rim lies this much below the ground around it (median): a basin


@dataclass(frozen=True)
class Blind:
    """The report's ``blind`` section and the bound (m3 per part) it adds to the interval."""

    report: dict
    bound: dict = field(default_factory=lambda: dict.fromkeys(("net", "cut", "fill"), 0.0))


def blind_change(
    diff: np.ndarray,
    epochs: tuple[EpochDEM, EpochDEM],
    change: np.ndarray,
    cell_area: float,
    seen_once: np.ndarray | None = None,
) -> Blind:
    """The holes without any point of either survey (``epochs``: after, before) whose rim is mostly
    in the ``change`` areas, and the range of the change under them (see module); ``seen_once``:
    cells of a large hole of one survey filled from its own ground around it, the other survey
    measuring a pile across it (their counted change is reported: it rests on that fill)."""
    bound = dict.fromkeys(("net", "cut", "fill"), 0.0)
    items = []
    for name, e in zip(NAMES, epochs, strict=True):
        empty = (e.counts + e.nonsoil()) == 0
        labels, _ = scipy.ndimage.label(enclosed_holes(~empty, empty.size), FOUR)
        for k, box in enumerate(scipy.ndimage.find_objects(labels), 1):
            win = tuple(slice(max(b.start - PAD, 0), b.stop + PAD) for b in box)  # the hole and its rings
            cells = labels[win] == k
            if not _basin(e.heights[win], cells):
                continue
            item = _hole(diff[win], cells, change[win], cell_area)
            if item is None:
                continue
            reach = max(abs(v) for v in item["range_m3"])
            bound["cut" if item["rim_difference_m"] < 0 else "fill"] += reach
            bound["net"] += reach
            items.append({**item, "survey": name})
    area = sum(i["area_m2"] for i in items)
    report = {"count": len(items), "area_m2": area, "bound_m3": bound, "items": items}
    once = change & (seen_once if seen_once is not None else np.zeros(change.shape, bool))
    d = np.where(once, np.nan_to_num(diff), 0.0)
    report["interpolated"] = {
        "area_m2": float(once.sum()) * cell_area,
        "cut": float(-d[d < 0].sum()) * cell_area,
        "fill": float(d[d > 0].sum()) * cell_area,
    }
    return Blind(report, bound)


def _rings(cells: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(near, far): a hole's ``valid`` cells next to it, and those 3 to 4 cells out."""
    near = scipy.ndimage.binary_dilation(cells) & ~cells & valid
    far = (
        scipy.ndimage.binary_dilation(cells, iterations=4) & ~scipy.ndimage.binary_dilation(cells, iterations=2) & valid
    )
    return near, far


def _basin(h: np.ndarray, cells: np.ndarray) -> bool:
    """Whether the survey's own ground falls into the hole from around it (its rim, in the median,
    :data:`BASIN_DROP_M` below the ground a few cells further out): a pond or a pit's bottom. An
    occlusion beside a pile on flat ground, or on its flank, has none, and its refill stands."""
    near, far = _rings(cells, np.isfinite(h))
    if near.sum() < 4 or not far.any():
        return False
    total = scipy.ndimage.uniform_filter(np.where(far, h, 0.0), 7, mode="constant")
    count = scipy.ndimage.uniform_filter(far.astype(float), 7, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        around = np.where(count > 0, total / count, np.nan)  # the ground a few cells out, on average
    drop = (around - h)[near]
    return bool(np.nanmedian(drop) >= BASIN_DROP_M) if np.isfinite(drop).any() else False


def _hole(diff: np.ndarray, cells: np.ndarray, change: np.ndarray, cell_area: float) -> dict | None:
    """One hole's range (m3, relative to what the headline holds there), or None when its rim is
    not in the works or what it may hide is negligible."""
    ring = scipy.ndimage.binary_dilation(cells, iterations=2) & ~cells & np.isfinite(diff)
    if not ring.any() or float(np.mean(change[ring])) < RIM_SHARE:
        return None
    near, far = _rings(cells, np.isfinite(diff))
    d_near = float(np.median(diff[near])) if near.any() else 0.0
    d_far = float(np.median(diff[far])) if far.any() else d_near
    step = (d_near - d_far) / 2.5  # per cell, going in
    if step * d_near <= 0:  # the rim does not deepen inwards: nothing to carry on
        step = 0.0
    dist = scipy.ndimage.distance_transform_edt(cells)
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
