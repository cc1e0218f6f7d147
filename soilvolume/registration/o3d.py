"""Open3D helpers of the registration: clouds from numpy arrays, upward normals (Open3D imported on
first use, quiet)."""

from __future__ import annotations

import numpy as np


def _o3d():
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def to_pcd(xyz: np.ndarray, voxel: float | None = None):
    """Open3D cloud from local float64 coordinates, optionally voxel-thinned."""
    o3d = _o3d()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(xyz, dtype=np.float64)))
    return pcd.voxel_down_sample(voxel) if voxel else pcd


def with_normals(pcd, radius: float):
    """Upward-oriented normals (an empty cloud is returned as it is)."""
    o3d = _o3d()
    if not pcd.has_points():
        return pcd
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    pcd.orient_normals_to_align_with_direction(np.array([0.0, 0.0, 1.0]))
    return pcd
