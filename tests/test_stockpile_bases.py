"""The toe bases on toes of known heights: the lowest and highest levels not biased by the
noise of many toe heights (their extreme lies beyond the true one), a real departure from the
toe's plane kept, and each base's interval weights the base's own derivative."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.stockpile.bases import toe_base
from soilvolume.stockpile.interval import base_weights
from soilvolume.stockpile.toe import Toe
from soilvolume.stockpile.types import TOE_BASES

SIGMA = 0.0015  # m: a toe height's noise, as on the seeded yards (1-1.4 mm)


def _toe(z_of, seed: int, n: int = 180, radius: float = 12.0) -> tuple[Toe, np.ndarray]:
    """A round toe of ``n`` points with heights ``z_of(x, y)`` plus noise, and the true heights."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x, y = radius * np.cos(t), radius * np.sin(t)
    true = z_of(x, y)
    z = true + np.random.default_rng(seed).normal(0, SIGMA, n)
    weight = np.full(n, 2 * np.pi * radius / n)
    return Toe(x, y, z, weight, np.full(n, SIGMA), 0.006, 4.0), true


def _level(kind: str, toe: Toe) -> float:
    return float(toe_base(kind, toe, np.zeros(1), np.zeros(1))[0])


@pytest.mark.parametrize("tilt", [0.0, 0.06])
def test_lowest_and_highest_are_not_the_noise_extremes(tilt):
    """Over 40 toes on level and sloping ground the raw extreme of 180 noisy heights lies about
    2.5 sigma beyond the true one; the levels are within a sigma on average and 2.5 at worst."""
    errors = {"lowest": [], "highest": [], "raw": []}
    for seed in range(40):
        toe, true = _toe(lambda x, y: 100 + tilt * x, seed)  # noqa: B023 - used at once
        errors["raw"].append(np.max(toe.z) - np.max(true))
        errors["lowest"].append(_level("lowest", toe) - np.min(true))
        errors["highest"].append(_level("highest", toe) - np.max(true))
    assert np.mean(errors.pop("raw")) > (2 if not tilt else 0.5) * SIGMA  # the bias the levels remove
    for kind, e in errors.items():
        e = np.asarray(e) / SIGMA
        assert abs(np.mean(e)) < 1.0 and np.max(np.abs(e)) < 2.5, (kind, np.mean(e), np.max(np.abs(e)))


def test_a_real_rise_of_the_toe_is_kept():
    """A 5 cm hump over a stretch of level toe is no noise: the highest level stands on it,
    shrunk by less than a sigma."""
    toe, true = _toe(lambda x, y: 100 + 0.05 * np.clip(1 - np.hypot(x - 12, y) / 3, 0, None), seed=1)
    assert abs(_level("highest", toe) - np.max(true)) < 2 * SIGMA
    assert abs(_level("lowest", toe) - 100) < 2 * SIGMA


@pytest.mark.parametrize("kind", TOE_BASES)
def test_interval_weights_are_the_bases_derivatives(kind):
    """Moving one toe height moves the base's integral by that height's weight (the interval
    carries the toe's noise through them)."""
    toe, _ = _toe(lambda x, y: 100 + 0.03 * x + 0.05 * np.clip(1 - np.hypot(x - 12, y) / 3, 0, None), seed=2)
    g = np.linspace(-9, 9, 19)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    area = np.full(x.shape, 1.0)
    w = base_weights(kind, toe, x, y, area)
    for k in (0, int(np.argmax(toe.z)), 45, 90):
        dz = np.zeros_like(toe.z)
        dz[k] = 1e-7
        moved = Toe(toe.x, toe.y, toe.z + dz, toe.weight, toe.sigma, toe.noise, toe.reach)
        change = np.sum(area * (toe_base(kind, moved, x, y) - toe_base(kind, toe, x, y))) / 1e-7
        assert change == pytest.approx(w[k], rel=1e-3, abs=1e-3 * area.sum()), (kind, k)
