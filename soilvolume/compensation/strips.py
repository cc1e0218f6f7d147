"""Flight-strip steps left in a difference after its smooth bias surface: one survey's strips stand at offsets from
each other (a block adjustment's leftover), so the stable ground's residual is constant along a direction and steps
across it. The residual is binned across each direction; the bins cut into runs of constant level where a step is
significant (binary segmentation, a BIC penalty on the stable ground's noise); the direction whose steps explain
the most of the residual is kept when they explain enough of it, and its levels are subtracted everywhere (the
works included: a strip runs through them)."""

from __future__ import annotations

import math

import numpy as np

from ..core.types import GridSpec
from .robust import nmad

BIN_M = 1.0  # the residual's profile across a direction, in bins this wide
COARSE_DEG = 15.0  # directions searched this far apart, then about the best every STEP_DEG and a sixth of it
STEP_DEG = 3.0
MIN_STRIP_M = 8.0  # no run of constant level narrower than this (a flight strip is tens of metres wide)
MIN_STEP_M = 0.01  # nor a step smaller than this
MIN_SHARE = 0.3  # the steps must explain at least this share of the stable residual's variance
MIN_CELLS = 400  # stable cells needed to look for strips
MAX_CELLS = 40_000  # stable cells used (a regular subsample beyond)
MAX_RUNS = 12  # the binary segmentation goes this many runs deep at most (log2: its depth)


def strip_steps(residual: np.ndarray, stable: np.ndarray, grid: GridSpec) -> dict | None:
    """The strips of ``residual`` on the ``stable`` cells (their direction, where their runs start across it and
    their levels: :func:`strip_levels` puts them on a grid), or None when no direction's steps explain
    :data:`MIN_SHARE` of it."""
    mask = stable & np.isfinite(residual)
    if mask.sum() < MIN_CELLS:
        return None
    x, y = grid.centers_local()
    idx = np.flatnonzero(mask)[:: -(-int(mask.sum()) // MAX_CELLS)]
    px, py, r = x.ravel()[idx], y.ravel()[idx], residual.ravel()[idx]
    centre, spread = float(np.median(r)), nmad(r)
    if not spread > 0:
        return None
    r = np.clip(r, centre - 3 * spread, centre + 3 * spread)  # a stray patch of change is no strip
    total = float(np.sum((r - r.mean()) ** 2))
    gain, angle, lo, edges, levels = _search(px, py, r, spread, total)
    if len(levels) < 2 or gain < MIN_SHARE * total:
        return None
    starts = [float(lo + BIN_M * e) for e in edges]
    return {
        "angle_deg": float(angle),
        "starts_m": starts,
        "levels_m": [float(v) for v in levels],
        "explained": gain / total,
    }


def _search(px, py, r, spread: float, total: float) -> tuple:
    """The best direction's profile: every :data:`COARSE_DEG` first (strips blurred a little still step), then
    about the best every :data:`STEP_DEG` and a sixth of it, unless the coarse steps explain too little."""
    best = max((_profile(px, py, r, a, spread) for a in np.arange(0.0, 180.0, COARSE_DEG)), key=lambda p: p[0])
    if best[0] < 0.5 * MIN_SHARE * total:
        return best
    for step, reach in ((STEP_DEG, COARSE_DEG), (STEP_DEG / 6, STEP_DEG)):
        around = np.arange(best[1] - reach, best[1] + reach + 1e-9, step)
        best = max((best, *(_profile(px, py, r, a, spread) for a in around)), key=lambda p: p[0])
    return best


def strip_levels(strips: dict | None, grid: GridSpec) -> np.ndarray:
    """The ``strips``' level (m) on each cell of ``grid`` (any window of the frame they were found in); 0 without."""
    if not strips:
        return np.zeros((grid.rows, grid.cols))
    x, y = grid.centers_local()
    at = np.searchsorted(np.asarray(strips["starts_m"]), _across(x, y, strips["angle_deg"]), side="right") - 1
    return np.asarray(strips["levels_m"])[np.clip(at, 0, len(strips["levels_m"]) - 1)]


def _across(x: np.ndarray, y: np.ndarray, angle_deg: float) -> np.ndarray:
    t = math.radians(angle_deg)
    return x * math.cos(t) + y * math.sin(t)


def _profile(px, py, r, angle: float, noise: float) -> tuple[float, float, float, np.ndarray, list[float]]:
    """(the variance the runs explain, ``angle``, the profile's start, the runs' first bins, their levels)."""
    u = _across(px, py, angle)
    lo = float(u.min())
    b = ((u - lo) / BIN_M).astype(int)
    n, s = np.bincount(b).astype(float), np.bincount(b, weights=r)
    cuts = _runs(np.cumsum(np.r_[0.0, n]), np.cumsum(np.r_[0.0, s]), 0, len(n), noise**2, int(MIN_STRIP_M / BIN_M))
    edges = np.array([0, *cuts])
    bounds = [*cuts, len(n)]
    levels = [(s[a:z].sum() / max(n[a:z].sum(), 1.0)) for a, z in zip(edges, bounds, strict=True)]
    mean = r.mean()
    gain = float(sum(n[a:z].sum() * (v - mean) ** 2 for a, z, v in zip(edges, bounds, levels, strict=True)))
    return gain, angle, lo, edges, levels


def _runs(cn: np.ndarray, cs: np.ndarray, a: int, z: int, var: float, width: int, depth: int = 0) -> list[int]:
    """The bins where runs of constant level start in bins ``a``..``z`` (cumulative counts ``cn`` and sums ``cs``):
    the split of most variance explained, kept when significant (BIC) and a step of :data:`MIN_STEP_M`, recursively."""
    if z - a < 2 * width or depth > int(math.log2(MAX_RUNS)):
        return []
    k = np.arange(a + width, z - width + 1)
    n1, n2 = cn[k] - cn[a], cn[z] - cn[k]
    ok = (n1 > 0) & (n2 > 0)
    if not ok.any():
        return []
    m1 = np.where(ok, (cs[k] - cs[a]) / np.maximum(n1, 1), 0.0)
    m2 = np.where(ok, (cs[z] - cs[k]) / np.maximum(n2, 1), 0.0)
    gain = np.where(ok, n1 * n2 / np.maximum(n1 + n2, 1) * (m1 - m2) ** 2, 0.0)
    i = int(np.argmax(gain))
    if gain[i] < 2.0 * var * math.log(max(cn[z] - cn[a], 2.0)) or abs(m1[i] - m2[i]) < MIN_STEP_M:
        return []
    cut = int(k[i])
    left = _runs(cn, cs, a, cut, var, width, depth + 1)
    return [*left, cut, *_runs(cn, cs, cut, z, var, width, depth + 1)]
