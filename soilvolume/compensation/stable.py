"""Stable ground: the cells of a DEM of difference where nothing changed, even when works cover most
of the survey. From the footprint's margin (surveys are flown beyond the works) a low-order surface
is fitted robustly (Tukey IRLS); cells within k noise levels are stable, change areas dilated, the
surface refitted until the set stops changing. The noise comes from neighbouring cells'
differences, which smooth offsets, tilts or doming do not inflate."""

from __future__ import annotations

import numpy as np
import scipy

from .robust import fit_poly, nmad, patches

MARGIN_FRACTION = 0.15  # margin band width as a fraction of the footprint's inradius
K_NOISE, MIN_CHANGE_CELLS, ITERATIONS = 3.0, 3, 8  # change: beyond K noise levels, in patches of 3+ cells
DILATE_M = 2.0  # change areas dilated by a disk of this radius


def noise_sigma(diff: np.ndarray) -> float:
    """One-cell noise (m) of a difference grid: NMAD of differences between 4-neighbours / sqrt 2."""
    d = np.concatenate([(diff[:, 1:] - diff[:, :-1]).ravel(), (diff[1:] - diff[:-1]).ravel()])
    d = d[np.isfinite(d)]
    return nmad(d) / np.sqrt(2.0) if d.size >= 10 else float("nan")


def margin(valid: np.ndarray, cell: float, fraction: float = MARGIN_FRACTION) -> np.ndarray:
    """Valid cells within a band along the outer edge of the valid area (gaps inside it closed
    first): at least three cells, ``fraction`` of the largest inside distance."""
    if not valid.any():
        return valid
    region = scipy.ndimage.binary_fill_holes(scipy.ndimage.binary_closing(np.pad(valid, 3), iterations=2))
    inside = scipy.ndimage.distance_transform_edt(region)[3:-3, 3:-3]
    band = max(3.0, fraction * float(inside.max()))
    return valid & (inside <= band)


def find_stable(diff: np.ndarray, cell: float, *, user_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(stable mask, fitted degree-2 surface) of a difference grid, from its margin; ``user_mask``
    (True = stable) is taken as given (on valid cells)."""
    valid = np.isfinite(diff)
    y, x = np.mgrid[0 : diff.shape[0], 0 : diff.shape[1]] * float(cell)
    if user_mask is not None:
        stable = valid & user_mask.astype(bool)
        return stable, fit_poly(x, y, diff, stable, 2)[0] if stable.sum() >= 12 else np.zeros(diff.shape)
    if valid.sum() < 12:
        return valid, np.zeros(diff.shape)
    stable = margin(valid, cell)
    if stable.sum() < 12:
        stable = valid
    noise = noise_sigma(diff)
    r = DILATE_M / cell  # in cells
    n = int(np.ceil(r))
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    disk = xx * xx + yy * yy <= r * r + 1e-9
    surface = fit_poly(x, y, diff, stable, 1, robust=True)[0]  # (12 cells and more from here on)
    for it in range(ITERATIONS):
        resid = diff - surface
        spread = nmad(resid[stable])
        thr = K_NOISE * (max(spread, noise) if np.isfinite(noise) else spread)
        change = patches(valid & (np.abs(resid) > thr), MIN_CHANGE_CELLS)
        if change.any():
            change = scipy.ndimage.binary_dilation(change, disk)
        new = valid & ~change
        if new.sum() < 12 or (it > 0 and np.array_equal(new, stable)):  # converged: the surface is the one fitted on it
            break
        stable = new
        surface = fit_poly(x, y, diff, stable, 2, robust=True)[0]
    return stable, surface


def largest_gap_deg(stable: np.ndarray, change: np.ndarray) -> float:
    """Largest angular gap (deg) of the stable cells seen from the change's centre (>180: one side)."""
    if not change.any() or not stable.any():
        return 0.0
    cr, cc = np.argwhere(change).mean(axis=0)
    r, c = np.nonzero(stable)
    ang = np.sort(np.degrees(np.arctan2(r - cr, c - cc)))
    gaps = np.diff(np.r_[ang, ang[0] + 360.0])
    return float(gaps.max())
