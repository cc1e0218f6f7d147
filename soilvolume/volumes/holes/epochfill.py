"""Holes of one survey filled from that survey's own neighbours, where the other survey sees
change across them.

A hole of the difference is interpolated from the difference around it, which is smooth on
unchanged ground whatever the terrain (the terrain's detail inside the hole is the same in both
surveys and cancels). Where one survey has a hole and the other sees an object's wall or a
pile's flank across it, the difference is not smooth: interpolated across a 5 m wall, a
before-survey hole on a pillar's side dipped to -3...-5 m (accuracy harness, paper-pillars-rgb:
-19 m3 on a 299 m3 pillar). There the other survey's heights hold the change, and the survey
with the hole only misses its own ground: that ground is interpolated from its own neighbours
(its own detail is all the error) and the difference taken from the measured survey.

The choice is made per hole from what the data say: the measured survey's heights inside the
hole against their own interpolation from its rim (its detail there) are compared with how far
the survey with the hole departs from its own interpolation on holes of that size on its known
ground (its typical detail). Detail far beyond that is change, not shared terrain, when the
hole's rim shows change too (an object of the other survey standing wholly inside a hole, with
no change around it, is left to the difference: a machine that left over a hole of the later
survey is no soil cut). A hole with a quarter or more of its cells empty in both surveys is the
difference's to fill whole (a cell filled in its own survey beside them anchored that fill:
one moved a 72-cell hole by 13 m3).
"""

from __future__ import annotations

import numpy as np
import scipy

from .interpolate import FOUR, fill
from .testholes import error_by_radius

SHARED = 0.25  # a hole with this share of its cells empty in both surveys is the difference's whole
RIM = 2  # cells: the weak cells this close to a patch are filled with it
DETAIL_RATIO = 4.0  # the measured survey's detail beyond this many times the other's own: change
BULK_M3 = 120.0  # ... even with no change on its rim, when it holds more than a machine (a pile on a meadow)
PILE_M3 = 40.0  # a shared hole one survey sees a pile in: its departure beyond the terrain's detail, in all
BULK_MIN_M2 = 100.0  # ... a hole that large at least (smaller shared holes are the difference's to fill)


def fill_own_holes(
    h_a: np.ndarray, h_b: np.ndarray, hole: np.ndarray, weak: tuple, method: str, seed: int = 0, cell_area: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(after, before, cells filled in their own survey, their one-sigma error in m): the
    ``hole`` cells empty in one survey only whose other survey sees change across them (see
    module) interpolated in the survey they are missing from, with that survey's ``weak`` cells
    (after, before: refilled, or few points: partly covered beside a hole) next to them; the
    others are left to the difference's fill. The error is that survey's mean-height error on
    holes of the patch's size."""
    out, own, sigma = [h_a.copy(), h_b.copy()], np.zeros(hole.shape, bool), np.zeros(hole.shape)
    parts, m = scipy.ndimage.label(hole, FOUR)
    share = scipy.ndimage.mean(hole & ~np.isfinite(h_a) & ~np.isfinite(h_b), parts, np.arange(1, m + 1)) if m else []
    shared = np.r_[False, np.asarray(share) >= SHARED][parts]
    if cell_area > 0 and shared.any():
        bulk, bulk_sigma = _bulk_holes(out, parts, np.unique(parts[shared]), seed, cell_area)
        own |= bulk
        sigma[bulk] = bulk_sigma[bulk]
        shared &= ~bulk
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
        change[1:] &= (_rim_change(out[0] - out[1], labels, n) > detail / 2) | (bulk if cell_area > 0 else False)
        if change.any():  # a patch the survey cannot fill whole is left
            change &= (
                np.r_[False, scipy.ndimage.minimum(np.isfinite(fill(out[miss], change[labels], method)), labels, idx)]
                > 0
            )
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
    """Per patch, the change its rim shows (m): the larger of the rim's typical |difference| and
    its spread (upper minus lower decile); 0 without a measured rim."""
    grown = scipy.ndimage.grey_dilation(labels, footprint=np.ones((2 * RIM + 1,) * 2, bool))
    ring = (labels == 0) & (grown > 0) & np.isfinite(d)
    out = np.zeros(n)
    lab, val = grown[ring], d[ring]
    for k in np.unique(lab):
        v = val[lab == k]
        out[k - 1] = max(float(np.percentile(np.abs(v), 75)), float(np.percentile(v, 90) - np.percentile(v, 10)))
    return out


def _own_detail(h: np.ndarray, method: str, radius: np.ndarray, seed: int) -> np.ndarray:
    """Per patch radius (cells): the survey's own (per-cell RMS, mean-height) departures from
    its interpolation on test holes of about that radius cut from its known cells
    (:func:`.testholes.error_by_radius`); never taken for change where there is no room."""
    out = error_by_radius(h, np.isfinite(h), method, radius, seed, per_cell=True, floor=1e-9)
    return np.full((radius.size, 2), np.inf) if out is None else out


def _bulk_holes(out: list, parts: np.ndarray, ids: np.ndarray, seed: int, cell_area: float):
    """(cells filled, one-sigma error in m) of the shared holes in which a survey measures more
    than a machine's volume off its own interpolation (:data:`BULK_M3`: a pile raised on a meadow
    whose grass hides the ground of both surveys around it): each survey's missing cells there
    filled from its own known cells, harmonically (no overshoot beside the pile's foot), in place
    in ``out``; the error is the two surveys' mean-height errors on holes of the part's size."""
    done, sigma = np.zeros(parts.shape, bool), np.zeros(parts.shape)
    size = np.bincount(parts.ravel(), minlength=int(parts.max()) + 1)
    for k in ids[size[ids] * cell_area >= BULK_MIN_M2]:  # the small ones are the difference's to fill
        cells = parts == k
        region = scipy.ndimage.binary_fill_holes(cells)  # cells measured in both inside it anchor nothing
        departures = [_departure(e, region, cell_area) for e in out]
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


def _departure(e: np.ndarray, region: np.ndarray, cell_area: float) -> tuple[float, float]:
    """(RMS in m, volume in m3) of a survey's measured cells in ``region`` off its own harmonic
    interpolation across it: a pile stands out of the terrain's own detail and holds more than
    :data:`PILE_M3`; the ground's relief does not."""
    seen = region & np.isfinite(e)
    if not seen.any():
        return 0.0, 0.0
    dd = (e - fill(np.where(region, np.nan, e), region, "harmonic"))[seen]
    dd = dd[np.isfinite(dd)]
    if dd.size == 0:
        return 0.0, 0.0
    return float(np.sqrt(np.mean(dd * dd))), float(np.abs(dd).sum()) * cell_area
