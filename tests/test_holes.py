"""Sparse-cell refill and hole filling on synthetic differences with known volumes."""

from __future__ import annotations

import time

import numpy as np
import pytest

from soilvolume.volumes.change import refilled_budget as summary
from soilvolume.volumes.holes import solve, testholes
from soilvolume.volumes.holes.interpolate import (
    biharmonic_fill,
    enclosed_holes,
    harmonic_fill,
    refill_epoch,
)
from soilvolume.volumes.holes.testholes import disc_erosion_every

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


def test_large_harmonic_systems_use_conjugate_gradients(monkeypatch):
    """Above the direct solver's size the iterative path (SciPy's ``cg``) gives the direct answer."""
    rng = np.random.default_rng(3)
    values = rng.normal(0, 1, (50, 70)).cumsum(axis=1)
    targets = np.zeros(values.shape, bool)
    targets[5:45, 10:60] = True
    direct = harmonic_fill(values, targets)
    monkeypatch.setattr("soilvolume.volumes.holes.interpolate._DIRECT_MAX", 100)
    assert np.allclose(harmonic_fill(values, targets), direct, atol=1e-6)


def test_refill_epoch_recovers_pile_volume():
    """Cells of one epoch holding a single stray point (an outlier becomes the whole cell height)
    are refilled from that epoch's neighbours; the other epoch's heights are kept."""
    rng = np.random.default_rng(1)
    truth = pile()
    true_net = truth.sum() * CELL**2
    h_after = 50.0 + truth + rng.normal(0, 0.01, truth.shape)
    counts = rng.poisson(20, truth.shape) + 3
    sparse = rng.random(truth.shape) < 0.04
    counts[sparse] = 1
    h_after[sparse] += rng.choice([2.5, -1.5], sparse.sum())
    raw = np.nansum(h_after - 50.0) * CELL**2
    filled, mask = refill_epoch(h_after, counts, 0.1, min_points=3)
    net = np.nansum(filled - 50.0) * CELL**2
    assert abs(raw - true_net) / true_net > 0.1
    assert abs(net - true_net) / true_net < 0.01
    assert np.array_equal(mask, sparse)
    assert summary(filled - 50.0, mask, CELL**2)["filled_cells"] == mask.sum()


def test_refill_only_inside_footprint_and_bounded_holes():
    truth = pile(100, radius=8.0)
    h = truth.copy()
    h[:, :10] = np.nan  # outside this epoch's footprint
    h[40:44, 40:44] = np.nan  # a 16-cell occlusion hole on the pile
    h[70:80, 70:80] = np.nan  # a 100-cell hole
    counts = np.where(np.isfinite(h), 10, 0)
    filled, mask = refill_epoch(h, counts, 0.1, max_hole_cells=20)
    assert mask.sum() == 16
    assert np.isnan(filled[:, :10]).all() and np.isnan(filled[70:80, 70:80]).all()
    assert np.abs(filled[40:44, 40:44] - truth[40:44, 40:44]).max() < 0.01
    f2, m2 = refill_epoch(h, counts, 0.1, max_hole_cells=200)
    assert m2.sum() == 116 and np.isnan(f2[:, :10]).all()
    assert not enclosed_holes(np.isfinite(h), None).any()


def test_refill_is_fast_on_a_large_grid():
    rng = np.random.default_rng(2)
    h = rng.normal(0, 0.02, (1000, 1000))
    counts = rng.poisson(10, h.shape) + 3
    counts[rng.random(h.shape) < 0.05] = 1
    t0 = time.perf_counter()
    filled, mask = refill_epoch(h, counts, 0.1, min_points=3)
    assert time.perf_counter() - t0 < 5.0
    assert np.isfinite(filled).all() and mask.mean() > 0.04


# --------------------------------------------------------------------------- biharmonic / per epoch


def blobs(shape: tuple[int, int], frac: float, seed: int, r_max: float = 15.9) -> np.ndarray:
    """Random round target blobs (radius 1.5..r_max cells, up to ~800 cells) covering ~``frac``."""
    rng = np.random.default_rng(seed)
    t = np.zeros(shape, bool)
    while t.mean() < frac:
        a, b = rng.integers(20, shape[0] - 20), rng.integers(20, shape[1] - 20)
        r = rng.uniform(1.5, r_max)
        k = int(r) + 1
        yy, xx = np.mgrid[-k : k + 1, -k : k + 1]
        t[a - k : a + k + 1, b - k : b + k + 1] |= yy**2 + xx**2 < r * r
    return t


def cone(n: int = 80, height: float = 3.0, radius: float = 8.0):
    """A cone pile on flat ground in the middle of an n x n grid of CELL cells; (z, x, y)."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) * CELL
    r = np.hypot(x - n * CELL / 2, y - n * CELL / 2)
    return np.maximum(0.0, height * (1 - r / radius)), x, y


def test_biharmonic_reproduces_plane_and_quadratic():
    y, x = np.mgrid[0:60, 0:80].astype(float)
    targets = np.zeros(x.shape, bool)
    targets[10:30, 20:50] = True
    targets |= (y - 45) ** 2 + (x - 20) ** 2 < 36
    no_data = np.zeros(x.shape, bool)
    no_data[48:58, 60:78] = True
    for surface in (0.3 + 0.01 * x - 0.02 * y, 1 + 0.01 * x - 0.02 * y + 3e-3 * x * x - 2e-3 * x * y + 1e-3 * y * y):
        values = np.where(no_data, np.nan, surface)
        out = biharmonic_fill(values, targets)
        assert np.abs(out - surface)[targets].max() < 1e-6 * np.abs(surface).max()
        assert np.array_equal(out[~targets], values[~targets], equal_nan=True)  # untouched, NaN stays NaN
    harm = harmonic_fill(values, targets)
    assert np.abs(harm - surface)[targets].max() > 0.1  # harmonic is exact for planes only


def test_biharmonic_on_nan_edges_grid_border_and_unreachable_targets():
    y, x = np.mgrid[0:40, 0:50].astype(float)
    plane = 1 + 0.1 * x - 0.05 * y
    values = np.where(x < 6, np.nan, plane)  # a no-data strip
    targets = np.zeros(x.shape, bool)
    targets[3:15, 6:12] = True  # touches the strip
    targets[0:5, 30:38] = True  # touches the grid border
    targets[30:35, 0:3] = True  # inside the strip: nothing to interpolate from
    out = biharmonic_fill(values, targets)
    assert np.abs(out - plane)[3:15, 6:12].max() < 1e-9
    assert np.abs(out - plane)[0:5, 30:38].max() < 1e-9
    assert np.isnan(out[30:35, 0:3]).all() and np.isnan(out[:, :6][~targets[:, :6]]).all()
    line = np.full((20, 20), np.nan)
    line[:, 5] = 2.0  # collinear data only: ill posed for the biharmonic, harmonic fallback
    t = np.zeros(line.shape, bool)
    t[3:15, 6:12] = True
    assert np.allclose(biharmonic_fill(line, t)[t], 2.0)
    assert np.isnan(biharmonic_fill(np.full((4, 4), np.nan), np.ones((4, 4), bool))).all()


def test_biharmonic_cuts_the_kink_bias_of_a_hole_on_a_pile_foot():
    rng = np.random.default_rng(3)
    truth, x, y = cone()
    dem = truth + rng.normal(0, 0.01, truth.shape)
    hole = np.hypot(x - 28.0, y - 20.0) < 2.5  # radius 2.5 m, centred on the cone's foot (r = 8 m)
    dem[hole] = np.nan
    err_h = (harmonic_fill(dem, hole) - truth)[hole].sum() * CELL**2
    err_b = (biharmonic_fill(dem, hole) - truth)[hole].sum() * CELL**2
    # measured: 80 cells, true 3.63 m3 in the hole; harmonic +2.01 m3, biharmonic +0.87 m3
    assert err_h > 1.5 and abs(err_b) < 0.6 * abs(err_h)


def epoch_dem(seed: int = 4):
    """A cone DEM with Poisson counts, empty outside a partial footprint (left columns)."""
    rng = np.random.default_rng(seed)
    truth, _, _ = cone()
    counts = rng.poisson(20, truth.shape)
    counts[:, :8] = 0  # the cloud does not cover the left of the grid
    h = np.where(counts > 0, truth + rng.normal(0, 0.01, truth.shape), np.nan)
    return truth, h, counts, rng


def test_refill_epoch_refills_sparse_cells_and_bounded_enclosed_holes():
    truth, h, counts, rng = epoch_dem()
    weak = (rng.random(truth.shape) < 0.03) & (counts > 0)
    counts[weak] = 1
    h[weak] += rng.choice([2.0, -1.0], weak.sum())  # one stray point
    hole = np.zeros(truth.shape, bool)
    hole[30:36, 44:50] = True  # 36 cells on the pile's flank
    counts[hole] = 0
    h[hole] = np.nan
    thin = (counts > 0) & (counts < 0.5 * np.median(counts[counts > 0]))  # weak + a few Poisson lows
    assert weak.sum() > 100 and (thin & ~weak).sum() < 0.3 * weak.sum()
    filled, mask = refill_epoch(h, counts, 0.5, max_hole_cells=36)
    assert np.array_equal(mask, thin | hole)
    assert np.abs(filled - truth)[mask].max() < 0.2
    assert np.isnan(filled[:, :8]).all()  # the big border-touching empty area stays empty
    assert np.array_equal(filled[~mask], h[~mask], equal_nan=True)
    f2, m2 = refill_epoch(h, counts, 0.5, max_hole_cells=35, method="harmonic")
    assert np.array_equal(m2, thin) and np.isnan(f2[hole]).all()
    f3, m3 = refill_epoch(h, counts, 0.0, max_hole_cells=None)
    assert not m3.any() and np.array_equal(f3, h, equal_nan=True)
    with pytest.raises(ValueError):
        refill_epoch(h, counts, method="kriging")


def test_refill_epoch_takes_a_method():
    truth = pile(100, radius=8.0)
    h = truth.copy()
    h[40:44, 40:44] = np.nan
    counts = np.where(np.isfinite(h), 10, 0)
    for method, tol in (("harmonic", 0.1), ("biharmonic", 0.005)):
        filled, mask = refill_epoch(h, counts, 0.1, 20, method=method)
        assert mask.sum() == 16 and np.abs(filled - truth)[40:44, 40:44].max() < tol


def test_biharmonic_smoke_on_a_large_grid_with_blobs():
    n = 1500
    y, x = np.mgrid[0:n, 0:n].astype(float)
    surface = np.sin(x / 300) * 5 + np.cos(y / 200) * 3 + 1e-3 * x
    targets = blobs(surface.shape, 0.02, seed=5)
    values = np.where(x < 40, np.nan, surface)
    out = biharmonic_fill(values, targets)
    ok = targets & (x >= 40)
    assert np.isfinite(out[ok]).all() and np.abs(out - surface)[ok].max() < 0.02
    assert np.array_equal(out[~targets], values[~targets], equal_nan=True)


def test_biharmonic_wide_and_oversize_systems(monkeypatch):
    r, c = np.mgrid[0:60, 0:400].astype(float)
    quad = 1 + 0.01 * c + 0.02 * r + 1e-4 * c * c - 2e-4 * r * c
    wide = np.zeros(quad.shape, bool)
    wide[10:50, 20:380] = True  # rows of 360 unknowns: too wide for the banded solver, sparse LU
    assert np.abs(biharmonic_fill(quad, wide) - quad)[wide].max() < 1e-6 * np.abs(quad).max()
    truth, _, _ = cone()
    hole = np.zeros(truth.shape, bool)
    hole[30:40, 30:40] = True
    monkeypatch.setattr(solve, "_BIG_GROUP", 50)  # oversize sub-systems are filled harmonically
    assert np.array_equal(biharmonic_fill(truth, hole), harmonic_fill(truth, hole))


def _test_discs(h: np.ndarray, radius: float, seed: int = 0):
    """fill_error's test discs on h: (centres, offsets, targets)."""
    r = int(np.ceil(radius))
    step = 2 * r + 5
    cand = np.argwhere(disc_erosion_every(np.isfinite(h), radius + 2, step)) * step
    centres = cand[np.random.default_rng(seed).choice(len(cand), min(40, len(cand)), replace=False)]
    yy, xx = np.mgrid[-r - 2 : r + 3, -r - 2 : r + 3]
    disc = np.argwhere(xx * xx + yy * yy <= radius * radius) - (r + 2)
    targets = np.zeros(h.shape, bool)
    targets[centres[:, :1] + disc[:, 0], centres[:, 1:] + disc[:, 1]] = True
    return centres, disc, targets


@pytest.mark.parametrize("radius", [1.0, 2.5, 4.0, 8.0])
def test_test_discs_solved_at_once_fill_as_the_whole_system(radius):
    """The test discs of fill_error, apart and fully surrounded, share one factorised system
    (``_discs_filled``): the same heights as the biharmonic fill of them all (equal up to the
    last bits of the banded solver's blocking)."""
    rng = np.random.default_rng(int(radius * 10))
    y, x = np.mgrid[0:150, 0:170].astype(float)
    h = np.sin(x / 9.0) * 3 + 0.01 * x * y + rng.normal(0, 0.05, x.shape)
    h[:20, :30] = np.nan  # gaps: discs only where there is room
    h[rng.random(h.shape) < 0.001] = np.nan
    centres, disc, targets = _test_discs(h, radius)
    values = np.where(targets, np.nan, h)
    together = testholes.discs_filled(values, targets, centres, disc)
    whole = biharmonic_fill(values, targets)
    assert together is not None and targets.sum() >= 5 * len(disc)
    assert np.allclose(together[targets], whole[targets], rtol=0, atol=1e-9)
    assert np.array_equal(together[~targets], values[~targets], equal_nan=True)  # the rest untouched
    hole_next_to_gap = values.copy()
    hole_next_to_gap[centres[0, 0] + int(np.ceil(radius)) + 1, centres[0, 1]] = np.nan
    assert testholes.discs_filled(hole_next_to_gap, targets, centres, disc) is None  # not the same system: declined


def test_fill_error_measures_the_fill_it_stands_for():
    """fill_error of a noisy surface: the error of the biharmonic fill it measures (the discs
    solved at once) is the one of the fill of the discs as any holes."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:120, 0:140].astype(float)
    h = 0.02 * x + rng.normal(0, 0.1, x.shape)
    for radius in (1.0, 2.0, 4.0):
        cell, mean = testholes.fill_error(h, np.isfinite(h), "biharmonic", radius)
        centres, disc, targets = _test_discs(h, radius)
        err = biharmonic_fill(np.where(targets, np.nan, h), targets) - h
        assert cell == pytest.approx(np.sqrt(np.mean(err[targets] ** 2)), rel=1e-9)
        assert 0.02 < mean < cell < 0.3  # a mean over a disc's cells errs less than one cell


def test_disc_erosion_every_is_the_erosion_at_every_step():
    from scipy import ndimage

    rng = np.random.default_rng(6)
    for _ in range(200):
        shape = tuple(rng.integers(1, 70, 2))
        mask = rng.random(shape) < rng.uniform(0.7, 1.0)
        radius, step = float(rng.choice([0.5, 1, 2.5, 3, 6, 6.5, 10])), int(rng.integers(1, 15))
        r = int(np.ceil(radius))
        yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
        eroded = ndimage.binary_erosion(mask, xx * xx + yy * yy <= radius * radius)
        assert np.array_equal(disc_erosion_every(mask, radius, step), eroded[::step, ::step])


def test_written_dems_give_back_the_difference(tmp_path):
    """Issue 49: dem_after.tif - dem_before.tif - plane_offset.tif is difference.tif wherever the
    difference is valid, refilled cells (filled_mask.tif) included, on a seeded pair with holes."""
    import rasterio
    from conftest import write_scene

    from soilvolume.api import estimate
    from soilvolume.options import Options

    b, a, _ = write_scene(tmp_path / "pair", 3)
    estimate(b, a, tmp_path / "out", Options(min_count_ratio=0.7))

    def read(name):
        with rasterio.open(tmp_path / "out" / name) as ds:
            return ds.read(1, masked=True).astype(np.float64).filled(np.nan)

    diff, mask = read("difference.tif"), read("filled_mask.tif") == 1
    back = read("dem_after.tif") - read("dem_before.tif") - read("plane_offset.tif")
    valid = np.isfinite(diff)
    assert (valid & mask).sum() >= 5, (valid & mask).sum()
    assert np.abs(back - diff)[valid].max() <= 1e-4, np.nanmax(np.abs(back - diff)[valid])
