"""Open3D helpers: imported on first use (quiet), clouds from arrays, upward normals."""

from __future__ import annotations

import sys
import types
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

PLOTLY = "open3d.visualization.draw_plotly"
_LIMITED = False  # whether limit_threads set a limit (a later run without one lifts it)
_ASKED: list[int] = []  # the threads asked for, applied when Open3D is (or is next) imported


def _o3d():
    global _LIMITED
    if "open3d" not in sys.modules:
        _import_without_plotly()
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    if _ASKED:
        threads = _ASKED.pop()
        if (threads > 0 or _LIMITED) and hasattr(o3d.utility, "set_max_threads"):
            o3d.utility.set_max_threads(max(0, int(threads)))
            _LIMITED = threads > 0
    return o3d


def limit_threads(threads: int) -> None:
    """Open3D's CPU threads (0: all cores; 0.19+ runs on oneTBB, deaf to OMP_NUM_THREADS): only
    remembered until Open3D is imported; a process that never asked keeps Open3D's own setting."""
    _ASKED[:] = [threads]
    if "open3d" in sys.modules:
        _o3d()


@contextmanager
def one_thread() -> Iterator[None]:
    """Open3D on one thread inside: its parallel RANSAC splits the seeded draws by how the threads happen to be
    scheduled, so the same inputs gave another pose on a busy machine (isl-org/Open3D#7475)."""
    utility = _o3d().utility
    before = utility.get_max_threads()
    utility.set_max_threads(1)
    try:
        yield
    finally:
        utility.set_max_threads(before)


def _import_without_plotly() -> None:
    """Import Open3D without its Plotly/Dash drawing (~0.6 s): a placeholder module stands in while
    ``open3d`` imports, dropped after (an explicit import then gets the real one)."""

    def unavailable(*_args, **_kwargs):
        raise ImportError(f"import {PLOTLY} for Open3D's Plotly drawing")

    stub = types.ModuleType(PLOTLY)
    stub.get_plotly_fig = stub.draw_plotly = stub.draw_plotly_server = unavailable
    sys.modules[PLOTLY] = stub
    try:
        import open3d  # noqa: F401
    except ImportError:
        for name in [n for n in sys.modules if n == "open3d" or n.startswith("open3d.")]:
            del sys.modules[name]
    finally:
        if sys.modules.get(PLOTLY) is stub:
            del sys.modules[PLOTLY]


def to_pcd(xyz: np.ndarray, normals: np.ndarray | None = None, voxel: float | None = None):
    """Open3D cloud from local float64 coordinates, with ``normals``, or optionally voxel-thinned."""
    o3d = _o3d()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(xyz, dtype=np.float64)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(normals)
    return pcd.voxel_down_sample(voxel) if voxel else pcd


def with_normals(pcd, radius: float):
    """Upward-oriented normals (an empty cloud is returned as it is)."""
    o3d = _o3d()
    if not pcd.has_points():
        return pcd
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    pcd.orient_normals_to_align_with_direction(np.array([0.0, 0.0, 1.0]))
    return pcd
