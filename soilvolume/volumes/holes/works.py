"""Holes in and around the works, where the plain fill of the difference is wrong.

Across the outline: a smooth fill rounds the kink at a pile's foot or a pit's rim (paper-density: -1.76 %
of a 259 m3 pit, +0.45 % of 954 m3 of piles; -0.08 % and -0.00 % this way). The outline is carried
through the hole (its signed distance interpolated; the nearer rim cut a trench's edge like a pie: -3.6
and +4.0 m3), each side filled from its own rim, the difference a term (:func:`outline_sigma`); a cut that enters
and leaves the hole is carried on between (an occluded trench's floor had gone to the banks: :func:`_between`).

In one survey: the difference is not smooth across a wall (a hole on a pillar's side dipped 3-5 m: -19
m3 of 299 m3 in paper-pillars-rgb), so such a hole is filled in the survey missing it when the other's
detail there is far beyond the survey's own on holes that size and the rim shows change (a machine
gone over a hole is no cut); holes a quarter empty in both are the difference's (filling one's cells
moved a 72-cell hole by 13 m3).

Without any point (water, a shadow): from its rim, a pond reads the water, not the pit's bottom (0.8 m
of water: 82 % of a 2 m pit's cut). A basin mostly rimmed by change is a range, from its rim's fill to
the rim's slope carried inwards (at most :data:`DEEPER` times the rim's depth), widening the interval;
the verdict says why."""

from __future__ import annotations

import numpy as np
import scipy

from ..change import part_budget
from ..results import Epochs
from .interpolate import FOUR, enclosed_holes, fill, patches_touching
from .testholes import error_by_radius

PAD = 8  # cells of context around a hole's box (its rings and the ground they are compared with)
RING = 2  # cells: the rim of a hole that says what surrounds it
MIN_SHARE = 0.2  # each side holds at least this share of the rim, or the hole is left as it is
MIN_SIDE = 8  # and at least this many rim cells: enough to carry a slope (on coarse grids the kink is inside a cell)
SHARED = 0.25  # a hole with this share of its cells empty in both surveys is the difference's whole
RIM = 2  # cells: the weak cells this close to a patch are filled with it
DETAIL_RATIO = 4.0  # the measured survey's detail beyond this many times the other's own: change
BULK_M3 = 120.0  # ... even with no change on its rim, when it holds more than a machine (a pile on a meadow)
PILE_M3 = 40.0  # a shared hole one survey sees a pile in: its departure beyond the terrain's detail, in all
BULK_MIN_M2 = 100.0  # ... a hole that large at least (smaller shared holes are the difference's to fill)
RIM_SHARE = 0.5  # share of a hole's rim in change areas that makes it a hole in the works
DEEPER = 4.0  # the walls carried on into a hole go at most this many times the rim's depth further (water
# standing to 80 % of a pit's depth)
MIN_M3 = 0.5  # ranges below this are noise, not named
BASIN_DROP_M = 0.2  # a hole whose rim lies this much below the ground around it (median): a basin
LINES = 8  # lines through a hole's cell, 22.5 degrees apart (a 3-cell trench followed within a cell over 8)


def refill_across_outline(
    values: np.ndarray, hole: np.ndarray, change: np.ndarray, method: str, through: np.ndarray | None = None
) -> np.ndarray:
    """``values`` with each ``hole`` whose rim holds change and unchanged cells refilled side by side; a cut of
    ``through`` (change no survey saw anything but soil in) carried on across it where it enters and leaves."""
    known = np.isfinite(values) & ~hole
    change, stable = known & change, known & ~change
    out = values.copy()
    labels, n = scipy.ndimage.label(hole, FOUR)
    grown = labels  # each hole whose rim (on the labels grown by RING) may hold enough of both sides
    for _ in range(RING):
        grown = np.where(grown > 0, grown, scipy.ndimage.grey_dilation(grown, footprint=FOUR))
    idx = np.arange(n + 1)
    candidates = np.minimum(scipy.ndimage.sum(change, grown, idx), scipy.ndimage.sum(stable, grown, idx)) >= MIN_SIDE
    for k, box in enumerate(scipy.ndimage.find_objects(labels), start=1):
        if not candidates[k]:
            continue
        box = tuple(slice(max(0, s.start - PAD), s.stop + PAD) for s in box)
        cells = labels[box] == k
        rim = scipy.ndimage.binary_dilation(cells, FOUR, iterations=RING) & known[box]
        n_change, n_stable = int((rim & change[box]).sum()), int((rim & stable[box]).sum())
        if min(n_change, n_stable) < max(MIN_SIDE, MIN_SHARE * int(rim.sum())):
            continue
        # the works' side: the signed distance to the outline interpolated across the hole, else the nearer rim
        to_change = scipy.ndimage.distance_transform_edt(~change[box])
        to_stable = scipy.ndimage.distance_transform_edt(~stable[box])
        signed = np.where(change[box], to_stable - 1.0, np.where(stable[box], -to_change, np.nan))
        signed = fill(np.where(cells, np.nan, signed), cells, method)
        nearer_change = np.where(np.isfinite(signed), signed > 0, to_change < to_stable) | _between(
            cells, change[box] & (values[box] < 0) & (True if through is None else through[box]), stable[box]
        )
        for side, own in ((cells & nearer_change, change[box]), (cells & ~nearer_change, stable[box])):
            filled = fill(np.where(own | side, values[box], np.nan), side, method)
            ok = side & np.isfinite(filled)
            out[box][ok] = filled[ok]
    return out


def _between(cells: np.ndarray, change: np.ndarray, stable: np.ndarray) -> np.ndarray:
    """The ``cells`` that lie between two change cells on a line through them (the first known cell each way is
    change): a trench across a hole carries on through it (its outline's signed distance, interpolated, gave the
    middle of a 3-cell trench to the banks around the hole)."""
    if not change.any():
        return np.zeros(cells.shape, bool)
    known = np.pad(np.where(change, 1, np.where(stable, 2, 0)), 1, constant_values=3)  # 3: the box's edge
    r, c = np.nonzero(cells)
    angle = np.arange(2 * LINES) * np.pi / LINES  # each line both ways: k and k + LINES
    dr, dc = np.sin(angle)[:, None], np.cos(angle)[:, None]
    first = np.zeros((angle.size, r.size), known.dtype)
    for step in range(1, max(known.shape)):
        rr = np.clip(np.rint(r + step * dr).astype(int) + 1, 0, known.shape[0] - 1)
        cc = np.clip(np.rint(c + step * dc).astype(int) + 1, 0, known.shape[1] - 1)
        first = np.where(first > 0, first, known[rr, cc])
        if (first > 0).all():
            break
    out = (first[:LINES] == 1) & (first[LINES:] == 1)
    found = np.zeros(cells.shape, bool)
    found[r[out.any(axis=0)], c[out.any(axis=0)]] = True
    return found


def outline_sigma(
    delta: np.ndarray, diff: np.ndarray, parts: dict[str, np.ndarray], share: float, cell_area: float
) -> dict[str, float]:
    """One-sigma volume (m3) per part of ``delta`` summed over each hole in the part or along its edge (the side refill
    may have moved a hole's cells out of it), beyond the refilled ``share`` of the |difference|."""
    labels, n = scipy.ndimage.label(delta != 0, np.ones((3, 3), bool))
    idx = np.arange(1, n + 1)
    out = {}
    for k, m in parts.items():
        hit = np.isin(labels, patches_touching(labels, m))
        moved = np.abs(scipy.ndimage.sum(np.where(hit, delta, 0.0), labels, idx))
        given = share * scipy.ndimage.sum(np.where(m, np.abs(np.nan_to_num(diff)), 0.0), labels, idx)
        out[k] = float(np.linalg.norm(np.maximum(moved - given, 0.0))) * cell_area
    return out


def fill_own_holes(
    h_a: np.ndarray, h_b: np.ndarray, hole: np.ndarray, weak: tuple, method: str, seed: int = 0, cell_area: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(after, before, cells filled in their own survey, their one-sigma error m): ``hole`` cells the other sees change
    across filled, with ``weak`` cells beside them (see module)."""
    out, (parts, m) = [h_a.copy(), h_b.copy()], scipy.ndimage.label(hole, FOUR)
    share = scipy.ndimage.mean(hole & ~np.isfinite(h_a) & ~np.isfinite(h_b), parts, np.arange(1, m + 1)) if m else []
    shared = np.r_[False, np.asarray(share) >= SHARED][parts]
    own, sigma = _bulk_holes(out, parts, np.unique(parts[shared]), seed, cell_area)
    shared &= ~own
    for miss, seen in ((1, 0), (0, 1)):
        one = hole & ~shared & ~np.isfinite(out[miss]) & np.isfinite(out[seen])
        labels, n = scipy.ndimage.label(one, FOUR)
        if n == 0:
            continue
        idx = np.arange(1, n + 1)
        radius = np.sqrt(np.bincount(labels.ravel(), minlength=n + 1)[1:] / np.pi)
        seen_fill = fill(np.where(one, np.nan, out[seen]), one, method)
        detail = np.sqrt(scipy.ndimage.mean(np.nan_to_num(np.square(out[seen] - seen_fill)), labels, idx))
        scale = _own_detail(out[miss], method, radius, seed)
        change = np.r_[False, detail > DETAIL_RATIO * scale[:, 0]]
        # no machine: the measured survey's departure from its own fill is beyond any machine's volume
        bulk = np.abs(scipy.ndimage.sum(np.nan_to_num(out[seen] - seen_fill), labels, idx)) * cell_area > BULK_M3
        change[1:] &= (_rim_change(out[0] - out[1], labels, n) > detail / 2) | bulk
        if change.any():  # a patch the survey cannot fill whole is left
            whole = scipy.ndimage.minimum(np.isfinite(fill(out[miss], change[labels], method)), labels, idx)
            change &= np.r_[False, whole] > 0
        if not change.any():
            continue
        cells = change[labels]
        grown = scipy.ndimage.grey_dilation(np.where(cells, labels, 0), footprint=np.ones((2 * RIM + 1,) * 2, bool))
        cells |= weak[miss] & (grown > 0)
        filled = fill(out[miss], cells, method)
        ok = cells & np.isfinite(filled)
        out[miss][ok] = filled[ok]
        own |= ok
        sigma[ok] = np.r_[0.0, scale[:, 1]][np.maximum(labels, grown)][ok]
    return out[0], out[1], own, sigma


def _rim_change(d: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """Per patch, its rim's change (m): the larger of its typical |difference| and its 10-90 % spread."""
    grown = scipy.ndimage.grey_dilation(labels, footprint=np.ones((2 * RIM + 1,) * 2, bool))
    ring = (labels == 0) & (grown > 0) & np.isfinite(d)

    def change(v: np.ndarray) -> float:
        return max(float(np.percentile(np.abs(v), 75)), float(np.percentile(v, 90) - np.percentile(v, 10)))

    return scipy.ndimage.labeled_comprehension(d[ring], grown[ring], np.arange(1, n + 1), change, float, 0.0)


def _own_detail(h: np.ndarray, method: str, radius: np.ndarray, seed: int) -> np.ndarray:
    """Per radius, the survey's own (per-cell RMS, mean-height) fill error (infinite without room: never change)."""
    out = error_by_radius(h, np.isfinite(h), method, radius, seed, floor=1e-9)
    return np.full((radius.size, 2), np.inf) if out is None else out


def _bulk_holes(out: list, parts: np.ndarray, ids: np.ndarray, seed: int, cell_area: float):
    """(cells filled, one-sigma error m) of shared holes a survey sees a pile in (grass hiding a meadow's ground),
    filled harmonically in each survey, in ``out``."""
    done, sigma = np.zeros(parts.shape, bool), np.zeros(parts.shape)
    size = np.bincount(parts.ravel(), minlength=int(parts.max()) + 1)
    for k in ids[size[ids] * cell_area >= BULK_MIN_M2]:  # the small ones are the difference's to fill
        cells = parts == k
        region = scipy.ndimage.binary_fill_holes(cells)  # cells measured in both inside it anchor nothing
        departures = []  # each survey's cells in it off its own harmonic fill: (RMS m, m3; a pile's over PILE_M3)
        for e in out:
            dd = (e - fill(np.where(region, np.nan, e), region, "harmonic"))[region & np.isfinite(e)]
            dd = dd[np.isfinite(dd)]
            departures.append(
                (float(np.sqrt(np.mean(dd * dd))) if dd.size else 0.0, float(np.abs(dd).sum()) * cell_area)
            )
        if not any(m3 > PILE_M3 for _, m3 in departures):
            continue
        radius = np.array([np.sqrt(region.sum() / np.pi)])
        # the terrain's own detail at that size, on whichever survey has room to measure it
        scale = min(float(_own_detail(e, "harmonic", radius, seed)[0, 0]) for e in out)
        if not any(rms > DETAIL_RATIO * scale for rms, _ in departures):
            continue
        err = 0.0
        for e in out:
            missing = cells & ~np.isfinite(e)
            e[missing] = fill(e, missing, "harmonic")[missing]
            err = float(np.hypot(err, _own_detail(e, "harmonic", radius, seed)[0, 1]))
        ok = cells & np.isfinite(out[0]) & np.isfinite(out[1])
        done |= ok
        sigma[ok] = err
    return done, sigma


def blind_change(diff: np.ndarray, epochs: Epochs, change: np.ndarray, cell_area: float, seen_once: np.ndarray) -> dict:
    """The basins without any point in the ``change`` areas and their range (see module), and the change counted on
    ``seen_once`` cells (filled in one survey from its own ground)."""
    bound, items = dict.fromkeys(("net", "cut", "fill"), 0.0), []
    for name, e in zip(("after", "before"), epochs, strict=True):
        empty = e.all_points() == 0
        labels, _ = scipy.ndimage.label(enclosed_holes(~empty, empty.size), FOUR)
        for k, box in enumerate(scipy.ndimage.find_objects(labels), 1):
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
    b = part_budget(diff, once, cell_area)
    report["interpolated"] = {k: b[k] for k in ("area_m2", "cut", "fill")}
    return report


def _rings(cells: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(near, far): a hole's ``valid`` cells next to it, and those 3 to 4 cells out."""
    near = scipy.ndimage.binary_dilation(cells) & ~cells & valid
    far = (
        scipy.ndimage.binary_dilation(cells, iterations=4) & ~scipy.ndimage.binary_dilation(cells, iterations=2) & valid
    )
    return near, far


def _basin(h: np.ndarray, cells: np.ndarray) -> bool:
    """Whether the hole's rim lies (median) :data:`BASIN_DROP_M` below the ground a few cells out: a
    pond or a pit's bottom, not an occlusion beside or on a pile (whose refill stands)."""
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
    """One hole's range (m3, against the headline), or None off the works or when negligible."""
    ring = scipy.ndimage.binary_dilation(cells, iterations=2) & ~cells & np.isfinite(diff)
    if not ring.any() or float(np.mean(change[ring])) < RIM_SHARE:
        return None
    near, far = _rings(cells, np.isfinite(diff))
    d_near = float(np.median(diff[near])) if near.any() else 0.0
    d_far = float(np.median(diff[far])) if far.any() else d_near
    step = (d_near - d_far) / 2.5  # per cell, going in; none if the rim does not deepen inwards
    wall = np.hypot(*np.gradient(np.where(np.isfinite(diff), diff, d_near)))  # the walls as steep as seen at the rim
    step = 0.0 if step * d_near <= 0 else np.sign(step) * max(abs(step), float(np.percentile(wall[near], 75)))
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
