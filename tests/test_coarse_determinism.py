"""The coarse registration (FPFH + RANSAC) gives the same pose from the same inputs however busy the machine:
Open3D's parallel RANSAC splits its seeded draws by how its threads are scheduled (a composed site's net moved
by 0.3 m3 and another's by 8.6 m3 between two runs beside another process), so it runs on one thread."""

from __future__ import annotations

import numpy as np

from soilvolume.options import Options
from soilvolume.registration import register
from soilvolume.registration.o3d import _o3d


def _terrain(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-30.0, 30.0, (n, 2))
    z = 0.8 * np.sin(xy[:, 0] / 6.0) + 0.5 * np.cos(xy[:, 1] / 4.0) + 0.05 * rng.standard_normal(n)
    z += 2.0 * np.exp(-((xy[:, 0] - 8) ** 2 + (xy[:, 1] + 5) ** 2) / 20.0)
    return np.c_[xy, z]


def test_the_coarse_ransac_runs_on_one_thread_and_gives_back_the_others(monkeypatch):
    o3d = _o3d()
    reg = o3d.pipelines.registration
    real, seen = reg.registration_ransac_based_on_feature_matching, []

    def spy(*args, **kwargs):
        seen.append(o3d.utility.get_max_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(reg, "registration_ransac_based_on_feature_matching", spy)
    before = o3d.utility.get_max_threads()
    after = _terrain(40_000, 1) + [1.5, -1.0, 0.2]
    stage = register.coarse_stage(after, _terrain(40_000, 2), Options(coarse="fpfh"))
    assert seen == [1] and o3d.utility.get_max_threads() == before
    again = register.coarse_stage(after, _terrain(40_000, 2), Options(coarse="fpfh"))
    assert np.array_equal(stage.transform, again.transform)
