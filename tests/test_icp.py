"""The registration's own point-to-plane ICP (issue 22): the poses of Open3D's ``registration_icp``
with a Tukey kernel, its nearest-neighbour searches exact under the bounds that skip them, and a
default run that never imports Open3D."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_python, write_scene
from scipy.spatial import cKDTree

from soilvolume.registration import columns
from soilvolume.registration.icp import point_to_plane
from soilvolume.registration.nearest import Nearest
from soilvolume.registration.rigid import transform_points


def _terrain(n: int, seed: int, shift: float = 0.0) -> np.ndarray:
    """Rolling terrain with slopes in x and y (so that x/y are constrained) and 3 cm noise."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 60, (n, 2)) + shift
    z = 2.0 * np.sin(xy[:, 0] / 7.0) + 1.5 * np.cos(xy[:, 1] / 5.0) + 0.02 * xy[:, 0]
    return np.column_stack([xy, z + rng.normal(0, 0.03, n)])


def _pose(rz_deg: float, shift: tuple[float, float, float]) -> np.ndarray:
    a = np.radians(rz_deg)
    t = np.eye(4)
    t[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    t[:3, 3] = shift
    return t


@pytest.mark.parametrize(("voxel", "dist", "k"), [(1.0, 3.0, 1.0), (0.5, 1.5, 0.5), (0.5, 0.8, 0.25)])
def test_point_to_plane_gives_open3d_poses(voxel, dist, k):
    """From a pose 0.6 m and 0.3 deg off, each level reaches Open3D's pose to 1e-9 with its
    fitness and inlier RMSE (Open3D on the same column surfaces and normals)."""
    from soilvolume.registration.o3d import _o3d

    o3d = _o3d()
    reg = o3d.pipelines.registration
    before = _terrain(60_000, 1)
    after = transform_points(_terrain(25_000, 2, shift=5.0), np.linalg.inv(_pose(0.3, (0.6, -0.4, 0.2))))
    cols = columns.columns(before, voxel)
    tgt, nrm = cols.xyz, columns.normals(cols)
    src = columns.columns(after, voxel).xyz
    ours = point_to_plane(src, tgt, nrm, dist, np.eye(4), k)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt))
    target.normals = o3d.utility.Vector3dVector(nrm)
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
    crit = reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=30)
    est = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=k))
    theirs = reg.registration_icp(source, target, dist, np.eye(4), est, crit)
    assert np.abs(ours.transform - np.asarray(theirs.transformation)).max() < 1e-9
    assert ours.fitness == pytest.approx(theirs.fitness, abs=1e-12)
    assert ours.inlier_rmse == pytest.approx(theirs.inlier_rmse, abs=1e-9)
    assert np.abs(ours.transform[:3, 3] - [0.6, -0.4, 0.2]).max() < 0.6  # it moved towards the truth
    assert 1 <= ours.iterations <= 30


def test_nearest_equals_a_full_search_as_the_points_move():
    """Small steps, a swing between two poses, a jump and a drift off the target: wherever a point's
    nearest target is within the distance, Nearest finds the one a full k-d tree search finds, at
    the same distance; elsewhere it finds none."""
    rng = np.random.default_rng(3)
    target = rng.uniform(0, 20, (5000, 3)) * [1, 1, 0.1]
    points = (rng.uniform(0, 20, (2000, 3)) * [1, 1, 0.1]).T.copy()
    dist = 0.5
    nearest, tree = Nearest(target, dist, workers=1), cKDTree(target)
    poses = [_pose(0.0, (0, 0, 0))]
    for step in range(12):
        poses.append(_pose(0.01 * step, (0.003 * step, -0.002 * step, 0.001)))
    poses += [_pose(0.2, (0.04, 0.0, 0.0)), _pose(-0.2, (-0.04, 0.0, 0.0))] * 3  # a swing
    poses += [_pose(2.0, (1.5, 0.5, 0.0)), _pose(0.0, (15.0, 0.0, 0.0))]  # a jump, half off the target
    for t in poses:
        moved = t[:3, :3] @ points + t[:3, 3:4]
        d, j = nearest(moved)
        d_ref, j_ref = tree.query(moved.T, k=1, distance_upper_bound=dist)
        within = d_ref <= dist
        assert np.array_equal(d <= dist, within)
        assert np.array_equal(j[within], j_ref[within])
        assert np.allclose(d[within], d_ref[within], rtol=0, atol=1e-12)


def test_a_default_run_leaves_open3d_out_and_gicp_brings_it(tmp_path):
    """The default registration (point-to-plane ICP) runs without importing Open3D; ``fine="gicp"``
    still runs Open3D's GICP, and both give the true net volume within 2 %."""
    before, after, truth = write_scene(tmp_path)
    code = (
        "import json, sys\n"
        "from soilvolume import api\n"
        "from soilvolume.options import Options\n"
        "out = {}\n"
        "for fine in ('icp', 'gicp'):\n"
        f"    r = api.estimate({str(before)!r}, {str(after)!r}, {str(tmp_path)!r} + '/' + fine,"
        " Options(fine=fine, coarse='auto'))\n"
        "    out[fine] = ['open3d' in sys.modules, r.report['volume_m3']['net']]\n"
        "print(json.dumps(out))\n"
    )
    r = run_python(code, timeout=240)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["icp"][0] is False and out["gicp"][0] is True
    for _, net in out.values():
        assert abs(net - truth["net"]) < 0.02 * abs(truth["net"])


@pytest.mark.parametrize("period", [2, 3, 4, 8])
def test_an_icp_going_round_a_cycle_of_poses_ends_where_its_last_iteration_would(monkeypatch, period):
    """An ICP whose step from each pose takes it round a cycle of 2, 3, 4 or 8 poses (it would
    till its last iteration; the paper pair's coarse levels go round 4 and 8) stops once a pose
    repeats the one a period before, on the pose the last iteration would have reached: the same
    transform and fitness as running them all, and the RMSE to rounding (the points moved step
    by step round apart), whatever the iterations left."""
    from soilvolume.registration import icp

    rng = np.random.default_rng(5)
    target = np.c_[rng.uniform(0, 20, (2000, 2)), np.zeros(2000)]
    normals = np.tile([0.0, 0.0, 1.0], (2000, 1))
    source = target[:500] + [0.0, 0.0, 0.05]
    start = np.eye(4)
    start[2, 3] = -3 / 64  # three steps up to the cycle
    calls = []

    def cycling(pts, *_):  # a function of the pose, as ICP's step: heights 0 .. period-1 (x 1/64 m), then 0
        calls.append(1)
        level = round((float(pts[2].mean()) - 0.05) * 64)
        out = np.eye(4)
        out[2, 3] = (1 if level < period - 1 else -level) / 64  # exact in binary: poses repeat exactly
        return out

    monkeypatch.setattr(icp, "_step", cycling)
    for max_iter in range(24, 32):
        calls.clear()
        short = point_to_plane(source, target, normals, 1.0, start, 0.5, max_iter=max_iter)
        steps = len(calls)
        monkeypatch.setattr(icp, "CYCLE", -1.0)  # no pose repeats: every iteration runs
        calls.clear()
        full = point_to_plane(source, target, normals, 1.0, start, 0.5, max_iter=max_iter)
        monkeypatch.setattr(icp, "CYCLE", 1e-12)
        assert len(calls) == max_iter and steps == 3 + period
        assert np.array_equal(short.transform, full.transform), max_iter
        assert (short.fitness, short.iterations) == (full.fitness, max_iter)
        assert short.inlier_rmse == pytest.approx(full.inlier_rmse, rel=1e-12)  # the moved points round apart
