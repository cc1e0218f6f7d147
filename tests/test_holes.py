"""Sparse-cell refill and hole filling on synthetic differences with known volumes."""

from __future__ import annotations

import time

import numpy as np

from soilvolume.holes import enclosed_holes, fill_holes, harmonic_fill, refill_sparse, summary

CELL = 0.5


def pile(n: int = 200, height: float = 3.0, radius: float = 12.0) -> np.ndarray:
    """A cosine-bell pile in the middle of an n x n grid of CELL cells."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) * CELL
    r = np.hypot(x - n * CELL / 2, y - n * CELL / 2)
    return np.where(r < radius, height * (1 + np.cos(np.pi * r / radius)) / 2, 0.0)


def test_harmonic_fill_is_exact_on_a_plane():
    y, x = np.mgrid[0:60, 0:80].astype(float)
    plane = 0.3 + 0.01 * x - 0.02 * y
    targets = np.zeros(plane.shape, bool)
    targets[10:30, 20:50] = True
    out = harmonic_fill(plane, targets)
    assert np.allclose(out, plane, atol=1e-9)


def test_refill_sparse_recovers_pile_volume():
    rng = np.random.default_rng(1)
    truth = pile()
    true_net = truth.sum() * CELL**2
    diff = truth + rng.normal(0, 0.01, truth.shape)
    cb = rng.poisson(12, truth.shape)
    ca = rng.poisson(20, truth.shape)
    sparse = rng.random(truth.shape) < 0.04
    ca[sparse] = 1  # one stray point: an outlier becomes the whole cell height
    diff[sparse] += rng.choice([2.5, -1.5], sparse.sum())
    raw = np.nansum(diff) * CELL**2
    filled, mask = refill_sparse(diff, cb, ca, ratio=0.5)
    net = np.nansum(filled) * CELL**2
    assert abs(raw - true_net) / true_net > 0.1
    assert abs(net - true_net) / true_net < 0.01
    assert mask[sparse].all()  # plus a few genuinely thin cells of the Poisson counts
    assert summary(filled, mask, CELL**2)["filled_cells"] == mask.sum()


def test_refill_only_inside_common_footprint_and_bounded_holes():
    truth = pile(100, radius=8.0)
    diff = truth.copy()
    diff[:, :10] = np.nan  # outside the after footprint
    diff[40:44, 40:44] = np.nan  # a 16-cell occlusion hole on the pile
    diff[70:80, 70:80] = np.nan  # a 100-cell hole
    counts = np.where(np.isfinite(diff), 10, 0)
    filled, mask = refill_sparse(diff, counts, counts, max_hole_cells=20)
    assert mask.sum() == 16
    assert np.isnan(filled[:, :10]).all() and np.isnan(filled[70:80, 70:80]).all()
    assert np.abs(filled[40:44, 40:44] - truth[40:44, 40:44]).max() < 0.1
    f2, m2 = fill_holes(diff, 200)
    assert m2.sum() == 116 and np.isnan(f2[:, :10]).all()
    assert not enclosed_holes(np.isfinite(diff), None).any()


def test_refill_is_fast_on_a_large_grid():
    rng = np.random.default_rng(2)
    diff = rng.normal(0, 0.02, (1000, 1000))
    cb = rng.poisson(10, diff.shape)
    ca = rng.poisson(10, diff.shape)
    ca[rng.random(diff.shape) < 0.05] = 1
    t0 = time.perf_counter()
    filled, mask = refill_sparse(diff, cb, ca)
    assert time.perf_counter() - t0 < 5.0
    assert np.isfinite(filled).all() and mask.mean() > 0.04
