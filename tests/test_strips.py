"""Flight-strip steps found in the stable ground's residual and taken out (:mod:`soilvolume.compensation.strips`)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from soilvolume.compensation.strips import strip_levels, strip_steps
from soilvolume.core.types import GridSpec

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import calibration  # noqa: E402

CELL = 0.5


def _grid(n: int = 160) -> GridSpec:
    return GridSpec(xmin=0.0, ymax=n * CELL, cell=CELL, rows=n, cols=n)


def _strips(grid: GridSpec, angle: float, width: float, step: float) -> np.ndarray:
    x, y = grid.centers_local()
    u = x * math.cos(math.radians(angle)) + y * math.sin(math.radians(angle))
    return np.where(np.floor(u / width) % 2 == 1, step, 0.0)


@pytest.mark.parametrize("angle", [0.0, 18.4, 75.0, 153.0])
def test_alternate_strips_are_found_and_their_steps_measured(angle):
    """Strips 25 m wide, every other one 4 cm up, under 2 cm of noise on stable ground with a works' hole in it:
    the direction within a degree, each cell's level within 1 cm but at the strips' edges (a bin)."""
    grid = _grid()
    rng = np.random.default_rng(int(angle))
    truth = _strips(grid, angle, 25.0, 0.04)
    residual = truth - truth.mean() + rng.normal(0.0, 0.02, truth.shape)
    stable = np.ones(truth.shape, bool)
    stable[50:110, 40:100] = False  # the works: no stable ground, the strips run on through them
    found = strip_steps(residual, stable, grid)
    assert found is not None
    assert abs((found["angle_deg"] - angle + 90.0) % 180.0 - 90.0) < 1.0, found
    levels = strip_levels(found, grid)
    off = np.abs((levels - levels.mean()) - (truth - truth.mean()))
    assert np.mean(off < 0.01) > 0.9, np.mean(off < 0.01)
    assert np.mean(off[50:110, 40:100] < 0.01) > 0.9  # in the works too


@pytest.mark.parametrize("kind", ["noise", "dome", "patch"])
def test_no_strips_are_made_of_noise_a_dome_or_a_patch_of_change(kind):
    """A residual of noise, of a smooth dome left by a plane fit, or with one patch of change on the stable
    ground: no strips."""
    grid = _grid()
    rng = np.random.default_rng(7)
    x, y = grid.centers_local()
    residual = rng.normal(0.0, 0.02, x.shape)
    if kind == "dome":
        residual += 0.05 * (1 - ((x - 40) ** 2 + (y - 40) ** 2) / 40**2)
    if kind == "patch":
        residual[20:40, 20:60] += 0.3
    assert strip_steps(residual, np.ones(x.shape, bool), grid) is None


def test_a_composed_site_with_flight_strips_is_measured_through_them(tmp_path):
    """Composed site 10472 (a 157 m3 trench; the after survey's 32 m strips stepped 5 cm up and 16 cm across):
    its cut had been 12 m3 over, outside its interval (+-12); the strips are found at their angle (18.4 deg),
    and the cut is within 5 m3, inside its interval."""
    (tmp_path / "rows").mkdir()
    (tmp_path / "scenes").mkdir()
    row = calibration.run_site(10472, tmp_path, ("test", "test"), keep=True)
    assert "georef: flight strips" in row["kinds"]
    assert abs(row["err_m3"]["cut"]) < 5.0 and all(row["covered"].values()), (row["err_m3"], row["half_width"])
