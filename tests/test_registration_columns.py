"""The registration's column surfaces: a target's remembered box cuts give the same column means,
bit for bit, as the whole cloud, and a cut holds every point of its box in the cloud's order."""

import numpy as np
import pytest

from soilvolume.registration.columns import Cloud, columns, normals


def _cloud(n: int = 60_000, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-40.0, 40.0, (n, 2))
    z = 0.02 * xy[:, 0] + np.sin(xy[:, 1] / 7.0) + rng.normal(0.0, 0.01, n)
    return np.c_[xy, z]


def _reference(xyz: np.ndarray, cell: float, lo: np.ndarray, hi: np.ndarray):
    """Column means by a plain sequential sum over the points in file order."""
    shape = (int((hi[1] - lo[1]) // cell) + 1, int((hi[0] - lo[0]) // cell) + 1)
    ix = np.floor((xyz[:, 0] - lo[0]) / cell).astype(np.int64)
    iy = np.floor((xyz[:, 1] - lo[1]) / cell).astype(np.int64)
    ok = (ix >= 0) & (iy >= 0) & (ix < shape[1]) & (iy < shape[0])
    ids = iy[ok] * shape[1] + ix[ok]
    sums = np.zeros((shape[0] * shape[1], 3))
    np.add.at(sums, ids, xyz[ok])
    count = np.bincount(ids, minlength=shape[0] * shape[1])
    has = np.flatnonzero(count)
    return sums[has] / count[has, None], has, shape


def test_cuts_give_the_whole_clouds_columns_bit_for_bit():
    xyz = _cloud()
    target = Cloud(xyz)
    rng = np.random.default_rng(7)
    lo0 = np.array([-30.0, -25.0])
    for _ in range(12):  # nearby boxes, as the fine stage asks for: most are served from a cut
        cell = float(rng.choice([0.25, 0.31, 0.5, 1.0]))
        lo = lo0 + rng.uniform(-3.0, 3.0, 2)
        hi = lo + np.array([55.0, 50.0]) + rng.uniform(-3.0, 3.0, 2)
        got = columns(target, cell, lo, hi)
        means, has, shape = _reference(xyz, cell, lo, hi)
        assert got.shape == shape
        assert np.array_equal(got.row * shape[1] + got.col, has)
        assert got.xyz.tobytes() == means.tobytes()
        assert normals(got).tobytes() == normals(columns(xyz, cell, lo, hi)).tobytes()
    assert 1 <= len(target._cuts) < 12


def test_a_cut_holds_every_point_of_its_box_in_order():
    xyz = _cloud(20_000)
    xyz[:, 2] = np.arange(len(xyz))  # heights tag the points' order
    target = Cloud(xyz)
    for lo, hi in [((-20.0, -20.0), (20.0, 20.0)), ((-18.0, -19.0), (19.0, 18.0)), ((0.0, 0.0), (5.0, 5.0))]:
        lo, hi = np.array(lo), np.array(hi)
        got = target.within(lo, hi)
        inside = (xyz[:, 0] >= lo[0]) & (xyz[:, 0] <= hi[0]) & (xyz[:, 1] >= lo[1]) & (xyz[:, 1] <= hi[1])
        assert set(xyz[inside, 2]) <= set(got[:, 2])
        assert np.all(np.diff(got[:, 2]) > 0)
    assert target.within(np.array([-50.0, -50.0]), np.array([50.0, 50.0])) is xyz
    assert len(columns(Cloud(xyz[:0]), 0.5, np.zeros(2), np.ones(2)).xyz) == 0


def test_threads_reach_open3d():
    """``--threads`` limits Open3D's own (oneTBB) threads, which OMP_NUM_THREADS does not reach."""
    from soilvolume.registration.o3d import _o3d, limit_threads

    utility = _o3d().utility
    if not hasattr(utility, "get_max_threads"):
        pytest.skip("this Open3D follows OMP_NUM_THREADS")
    default = utility.get_max_threads()
    try:
        limit_threads(1)
        assert utility.get_max_threads() == 1
    finally:
        limit_threads(0)
    assert utility.get_max_threads() == default


def test_a_thread_limit_asked_before_open3d_is_imported_reaches_it():
    """``--threads`` before anything imported Open3D (the default registration never does) is kept
    and applied when a GICP, PFH or FPFH step imports it."""
    from conftest import run_python

    code = (
        "import sys\n"
        "from soilvolume.registration.o3d import _o3d, limit_threads\n"
        "limit_threads(1)\n"
        "before = 'open3d' in sys.modules\n"
        "u = _o3d().utility\n"
        "print(before, u.get_max_threads() if hasattr(u, 'get_max_threads') else 1)\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "1"]


def test_points_moved_in_chunks_are_moved_as_in_one_product():
    """transform_points32 moves a cloud chunk by chunk: every point gets the bits of one matrix
    product over the whole cloud, a lone last row too (alone it would go through a matrix-vector
    product, which rounds otherwise)."""
    from soilvolume.registration.rigid import transform_points32

    rng = np.random.default_rng(1)
    t = np.eye(4)
    a = 0.3
    t[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    t[:3, 3] = [1.5, -2.25, 0.125]
    for k in (2, 3, 5, 8, 16, 64):
        for n in (k + 1, 2 * k, 3 * k + 1):
            xyz = rng.uniform(-500, 500, (n, 3)).astype(np.float32)
            assert np.array_equal(transform_points32(xyz, t, chunk=k), transform_points32(xyz, t, chunk=n)), (k, n)


def test_points_moved_as_columns_have_the_bits_of_the_row_product():
    """transform_points32 computes R @ xyz.T (the fast shape for BLAS): every coordinate has the
    bits of ``xyz @ R.T + shift`` in float32, for chunk sizes around the kernels' widths."""
    from soilvolume.registration.rigid import transform_points32

    rng = np.random.default_rng(2)
    a, b = np.deg2rad(2.5), 0.003
    t = np.eye(4)
    t[:3, :3] = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]]
    )
    t[:3, 3] = [1.2, -0.7, 0.3]
    r, s = t[:3, :3].T.astype(np.float32), t[:3, 3].astype(np.float32)
    for n in (*range(2, 40), 127, 129, 4097, 32769, 200_003):
        xyz = (rng.random((n, 3)) * [300, 300, 20] - [150, 150, 10]).astype(np.float32)
        moved = transform_points32(xyz, t, chunk=max(2, n // 3))
        assert moved.shape == (n, 3) and moved.dtype == np.float32
        assert np.ascontiguousarray(moved).tobytes() == (xyz @ r + s).tobytes(), n


def test_no_points_and_one_point_are_moved_too():
    """A chunk with no points (a tile task's chunk whose points all lie outside its read box) and
    one with a single point come back with their shapes (an empty one used to fail)."""
    from soilvolume.registration.rigid import transform_points32

    t = np.eye(4)
    t[:3, 3] = [1.0, 2.0, 3.0]
    assert transform_points32(np.empty((0, 3), np.float32), t).shape == (0, 3)
    assert np.array_equal(transform_points32(np.zeros((1, 3), np.float32), t), [[1.0, 2.0, 3.0]])
