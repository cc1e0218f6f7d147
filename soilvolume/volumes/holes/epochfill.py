"""Holes of one survey filled from its own neighbours where the other sees change across them: the
difference is not smooth across a wall (a hole on a pillar's side dipped 3-5 m: -19 m3 of 299 m3 in
paper-pillars-rgb). So when the other's detail there is far beyond the survey's own on holes that
size and the rim shows change (a machine gone over a hole is no cut); holes a quarter empty in both
are the difference's (filling one's cells moved a 72-cell hole by 13 m3)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

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
    """(after, before, cells filled in their own survey, their one-sigma error m): ``hole`` cells the other sees change
    across filled, with ``weak`` cells beside them (see module)."""
    out, own, sigma = [h_a.copy(), h_b.copy()], np.zeros(hole.shape, bool), np.zeros(hole.shape)
    parts, m = ndimage.label(hole, FOUR)
    share = ndimage.mean(hole & ~np.isfinite(h_a) & ~np.isfinite(h_b), parts, np.arange(1, m + 1)) if m else []
    shared = np.r_[False, np.asarray(share) >= SHARED][parts]
    if cell_area > 0 and shared.any():
        bulk, bulk_sigma = _bulk_holes(out, parts, np.unique(parts[shared]), seed, cell_area)
        own |= bulk
        sigma[bulk] = bulk_sigma[bulk]
        shared &= ~bulk
    for miss, seen in ((1, 0), (0, 1)):
        one = hole & ~shared & ~np.isfinite(out[miss]) & np.isfinite(out[seen])
        labels, n = ndimage.label(one, FOUR)
        if n == 0:
            continue
        idx = np.arange(1, n + 1)
        radius = np.sqrt(np.bincount(labels.ravel(), minlength=n + 1)[1:] / np.pi)
        seen_fill = fill(np.where(one, np.nan, out[seen]), one, method)
        detail = np.sqrt(ndimage.mean(np.nan_to_num(np.square(out[seen] - seen_fill)), labels, idx))
        scale = _own_detail(out[miss], method, radius, seed)
        change = np.r_[False, detail > DETAIL_RATIO * scale[:, 0]]
        # no machine: the measured survey's departure from its own fill is beyond any machine's volume
        bulk = np.abs(ndimage.sum(np.nan_to_num(out[seen] - seen_fill), labels, idx)) * cell_area > BULK_M3
        change[1:] &= (_rim_change(out[0] - out[1], labels, n) > detail / 2) | (bulk if cell_area > 0 else False)
        if change.any():  # a patch the survey cannot fill whole is left
            change &= (
                np.r_[False, ndimage.minimum(np.isfinite(fill(out[miss], change[labels], method)), labels, idx)] > 0
            )
        if not change.any():
            continue
        cells = change[labels]
        grown = ndimage.grey_dilation(np.where(cells, labels, 0), footprint=np.ones((2 * RIM + 1,) * 2, bool))
        cells |= weak[miss] & (grown > 0)
        filled = fill(out[miss], cells, method)
        ok = cells & np.isfinite(filled)
        out[miss][ok] = filled[ok]
        own |= ok
        sigma[ok] = np.r_[0.0, scale[:, 1]][np.maximum(labels, grown)][ok]
    return out[0], out[1], own, sigma


def _rim_change(d: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """Per patch, its rim's change (m): the larger of its typical |difference| and its 10-90 % spread."""
    grown = ndimage.grey_dilation(labels, footprint=np.ones((2 * RIM + 1,) * 2, bool))
    ring = (labels == 0) & (grown > 0) & np.isfinite(d)
    out = np.zeros(n)
    lab, val = grown[ring], d[ring]
    for k in np.unique(lab):
        v = val[lab == k]
        out[k - 1] = max(float(np.percentile(np.abs(v), 75)), float(np.percentile(v, 90) - np.percentile(v, 10)))
    return out


def _own_detail(h: np.ndarray, method: str, radius: np.ndarray, seed: int) -> np.ndarray:
    """Per radius, the survey's own (per-cell RMS, mean-height) fill error (infinite without room: never change)."""
    out = error_by_radius(h, np.isfinite(h), method, radius, seed, per_cell=True, floor=1e-9)
    return np.full((radius.size, 2), np.inf) if out is None else out


def _bulk_holes(out: list, parts: np.ndarray, ids: np.ndarray, seed: int, cell_area: float):
    """(cells filled, one-sigma error m) of shared holes a survey sees a pile in (grass hiding a meadow's ground),
    filled harmonically in each survey, in ``out``."""
    done, sigma = np.zeros(parts.shape, bool), np.zeros(parts.shape)
    size = np.bincount(parts.ravel(), minlength=int(parts.max()) + 1)
    for k in ids[size[ids] * cell_area >= BULK_MIN_M2]:  # the small ones are the difference's to fill
        cells = parts == k
        region = ndimage.binary_fill_holes(cells)  # cells measured in both inside it anchor nothing
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
    """(RMS m, volume m3) of a survey's cells in ``region`` off its own harmonic fill (a pile's over
    :data:`PILE_M3`)."""
    seen = region & np.isfinite(e)
    if not seen.any():
        return 0.0, 0.0
    dd = (e - fill(np.where(region, np.nan, e), region, "harmonic"))[seen]
    dd = dd[np.isfinite(dd)]
    if dd.size == 0:
        return 0.0, 0.0
    return float(np.sqrt(np.mean(dd * dd))), float(np.abs(dd).sum()) * cell_area
