"""The coarse registration: FPFH + RANSAC (Open3D) on column surfaces, within the GPS prior."""

from __future__ import annotations

import time

import numpy as np

from ..core.types import StageQuality
from ..options import Options
from . import columns
from .ground import cap_voxel
from .o3d import _o3d, to_pcd
from .rigid import rotation_deg, shift_at

MAX_COARSE_POINTS = 15_000
COARSE_ITER = 20_000  # RANSAC iterations of the coarse stage


def coarse_stage(after_xyz, before_xyz, options: Options) -> StageQuality:
    """``--coarse``: FPFH + RANSAC, accepted within the GPS prior (or forced by ``fpfh``)."""
    t0 = time.perf_counter()
    if options.coarse == "none":
        return StageQuality("none", float("nan"), float("nan"), np.eye(4), False, 0.0, "skipped")
    t = coarse_fpfh(after_xyz, before_xyz, options.coarse_voxel, options.seed)
    src, tgt = to_pcd(after_xyz, voxel=options.coarse_voxel), to_pcd(before_xyz, voxel=options.coarse_voxel)
    ev = _o3d().pipelines.registration.evaluate_registration(src, tgt, 1.5 * options.coarse_voxel, t)  # point to point
    fit, rmse = float(ev.fitness), float(ev.inlier_rmse)
    centre = after_xyz.mean(axis=0)
    rot, shift = rotation_deg(t), shift_at(t, centre)
    within = rot <= options.max_gps_rotation and shift <= options.max_gps_shift
    accepted = options.coarse == "fpfh" or within
    note = f"FPFH+RANSAC moved the after centre {shift:.2f} m and rotated {rot:.2f} deg"
    if not within:
        note += f"; outside the GPS error prior ({options.max_gps_shift} m, {options.max_gps_rotation} deg)" + (
            "" if accepted else ": rejected"
        )
    return StageQuality("fpfh-ransac", fit, rmse, t, accepted, time.perf_counter() - t0, note)


def coarse_fpfh(source_xyz: np.ndarray, target_xyz: np.ndarray, voxel: float, seed: int) -> np.ndarray:
    """FPFH features + RANSAC of the column surfaces on a coarse voxel (seeded); returns the 4x4 transform."""
    o3d = _o3d()
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(seed)
    voxel = max(voxel, cap_voxel(source_xyz, MAX_COARSE_POINTS), cap_voxel(target_xyz, MAX_COARSE_POINTS))
    src, tgt = (to_pcd(*columns.column_surface(xyz, voxel)) for xyz in (source_xyz, target_xyz))
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    fs, ft = reg.compute_fpfh_feature(src, param), reg.compute_fpfh_feature(tgt, param)
    dist = 1.5 * voxel
    res = reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        fs,
        ft,
        True,
        dist,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
        reg.RANSACConvergenceCriteria(COARSE_ITER, 0.999),
    )
    return np.asarray(res.transformation)
