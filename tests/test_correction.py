"""Stable-ground detection and bias-surface correction on a domed synthetic difference."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.compensation.correction import apply, fit_surface
from soilvolume.compensation.stable import find_stable
from soilvolume.core.types import GridSpec

CELL = 0.5
N = 200


def grid() -> GridSpec:
    return GridSpec(xmin=500000.0, ymax=4000000.0, cell=CELL, rows=N, cols=N, origin=(500000.0, 3999900.0, 0.0))


def domed_pair(seed: int = 0):
    """(diff, true pile): a 3 m pile and a 2.5 m pit, a 4 cm dome, a 5 cm bias, tilt, noise."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0:N, 0:N] + 0.5) * CELL
    r1 = np.hypot(x - 40, y - 55)
    r2 = np.hypot(x - 70, y - 30)
    truth = np.where(r1 < 12, 3.0 * (1 + np.cos(np.pi * r1 / 12)) / 2, 0.0)
    truth -= np.where(r2 < 6, 2.5 * (1 + np.cos(np.pi * r2 / 6)) / 2, 0.0)
    u, v = (x - 50) / 50, (y - 50) / 50
    dome = 0.04 * (1 - u * u - v * v) + 0.05 + 0.01 * u
    return truth + dome + rng.normal(0, 0.02, truth.shape), truth


def net_over_change(res) -> float:
    return float(np.nansum(np.where(res.change_mask, res.corrected, 0.0)) * CELL**2)


def test_surface_removes_doming_and_bias():
    diff, truth = domed_pair()
    true_net = truth.sum() * CELL**2
    errors = {}
    for method in ("surface", "plane", "none"):
        res = apply(diff, method, grid())
        errors[method] = abs(net_over_change(res) - true_net) / abs(true_net)
    assert errors["surface"] < 0.01
    assert errors["plane"] > 3 * errors["surface"]
    assert errors["none"] > 3 * errors["surface"]
    res = apply(diff, "surface", grid())
    assert res.params["residuals"]["nmad"] == pytest.approx(0.02, rel=0.15)
    assert abs(res.params["residuals"]["mean"]) < 0.005


def test_stable_cells_exclude_change_areas_with_a_margin():
    diff, truth = domed_pair(1)
    stable = find_stable(diff, CELL)[0]
    assert not (stable & (np.abs(truth) > 0.05)).any()
    assert stable.mean() > 0.7
    user = np.zeros(diff.shape, bool)
    user[:20] = True
    assert (find_stable(diff, CELL, user_mask=user)[0] == user).all()


def test_fit_surface_recovers_a_known_polynomial():
    g = grid()
    x, y = g.centers_local()
    poly = 0.1 + 0.002 * x - 0.001 * y + 1e-5 * x * x + 2e-5 * x * y
    surface, params = fit_surface(poly, np.ones(poly.shape, bool), g, "surface")
    assert np.allclose(surface, poly, atol=1e-9)
    assert params["residuals"]["n_cells"] == N * N and len(params["coefficients"]) == 6
    plane, p2 = fit_surface(poly, np.ones(poly.shape, bool), g, "plane")
    assert len(p2["coefficients"]) == 3
    none, p3 = fit_surface(poly, np.ones(poly.shape, bool), g, "none")
    assert not none.any() and p3["residuals"]["mean"] == pytest.approx(poly.mean())
    with pytest.raises(ValueError):
        fit_surface(poly, np.ones(poly.shape, bool), g, "spline")
