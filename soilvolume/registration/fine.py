"""The fine registration: ICP (:mod:`.icp`) or Open3D's GICP on column surfaces from the best start,
refined on stable ground; or the paper's PFH + SAC-IA (:mod:`.pfh`)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..core.cells import bounds
from ..core.types import SoilVolumeError, StageQuality
from ..options import Options
from . import columns, icp
from .ground import best_on, cap_voxel, evaluate_surface, judged, spacing, stable_source
from .nearest import Nearest, tree_of
from .o3d import _o3d, to_pcd
from .pfh import pfh_sac_ia
from .rigid import rotation_deg, shift_at, tilt_deg, transform_points

# (voxel m, max correspondence distance m, Tukey k m): coarse-to-fine, shrinking distances.
ICP_LEVELS = ((1.0, 6.0, 3.0), (1.0, 3.0, 1.0), (0.5, 1.5, 0.5), (0.25, 0.8, 0.25), (0.25, 0.4, 0.15))
REFINE_LEVELS = ((0.5, 0.8, 0.25), (0.25, 0.4, 0.12))
MAX_ICP_POINTS = 150_000  # per level: coarser voxels on very large sites
MAX_SOURCE_POINTS = 30_000  # ICP source points per level (the target keeps its density)
ICP_TOL, ICP_ITER = 1e-6, 30


def finest_column(after_xyz: np.ndarray, gap: float) -> float:
    """The side (m) of the finest columns matched (the last level's, at least the spacing ``gap`` and
    the large-cloud cap): the horizontal resolution of the registration."""
    return max(ICP_LEVELS[-1][0], gap, cap_voxel(after_xyz, MAX_ICP_POINTS))


def within_prior(t: np.ndarray, centre: np.ndarray, options: Options) -> bool:
    """Whether a pose stays within the georeferencing prior (shift at ``centre``, rotation, tilt)."""
    return (
        shift_at(t, centre) <= options.max_gps_shift
        and rotation_deg(t) <= options.max_gps_rotation
        and tilt_deg(t) <= options.max_gps_tilt
    )


def fine_stage(after_xyz, before_xyz, starts, options: Options, check, dense=None) -> StageQuality:
    """The fine stage from the best start: ICP/GICP run their 1 m levels from each and finish from the
    best; PFH and none are scored whole. ``before_xyz``: an array or a :class:`.columns.Cloud`."""
    t0 = time.perf_counter()
    gap = spacing(columns.Cloud.points(before_xyz))
    judge = judged(after_xyz, gap)
    if options.fine in ("icp", "gicp"):
        return replace(
            _icp_from_best(judge, after_xyz, before_xyz, starts, options, check, gap), seconds=time.perf_counter() - t0
        )
    best: StageQuality | None = None
    src, tgt = dense if dense is not None else (after_xyz, columns.Cloud.points(before_xyz))
    for init, label in starts:
        t = pfh_sac_ia(src, tgt, init, options.pfh_patch, options.seed) if options.fine == "pfh" else init
        fit, rmse = evaluate_surface(judge, before_xyz, t, gap=gap)
        q = StageQuality(options.fine, fit, rmse, t, True, 0.0, f"started from the {label} pose")
        far = best is not None and abs(q.fitness - best.fitness) > 0.005  # else the lower RMSE wins
        if best is None or (q.fitness > best.fitness if far else q.rmse < best.rmse):
            best = q
    assert best is not None
    return replace(best, seconds=time.perf_counter() - t0)


def _icp_from_best(src, after_xyz, before_xyz, starts, options: Options, check, gap: float) -> StageQuality:
    """ICP from the best start on the after survey's margin (``src``), refined on the stable ground at
    the pose reached; the pose fitting the margin best within the prior wins, the other refined pose
    its ``alternative``, those beyond the prior counted."""
    scored = [(icp_levels(src, before_xyz, init, ICP_LEVELS[:2], options, check, gap), lab) for init, lab in starts]
    (t, _, _), label = min(scored, key=lambda s: (round(-s[0][1], 3), s[0][2]))  # the best fit, then RMSE
    t = icp_levels(src, before_xyz, t, ICP_LEVELS[2:], options, check, gap)[0]
    poses = [*starts, (t, label)]
    src_stable = stable_source(after_xyz, before_xyz, t, gap=gap)
    if len(src_stable) > 100:  # a refinement on the stable ground found at the pose, already in the before frame
        t = icp_levels(src_stable, before_xyz, np.eye(4), REFINE_LEVELS, options, check, gap)[0] @ t
        poses.append((t, label))
    centre = after_xyz.mean(axis=0)
    allowed = [p for p in poses if within_prior(p[0], centre, options)] or poses[:1]
    best, (fit, rmse) = best_on(src, before_xyz, allowed, gap)
    others = [p[0] for p in allowed[len(starts) :] if p[0] is not best[0]]
    rejected = len(poses) - len(allowed)
    label = best[1] + (f"; {rejected} pose(s) beyond the georeferencing prior rejected" if rejected else "")
    return StageQuality(
        options.fine,
        fit,
        rmse,
        best[0],
        note=f"started from the {label} pose",
        alternative=others[-1] if others else None,
        beyond_prior=rejected,
        poses=tuple(p[0] for p in poses[len(starts) :]),
    )


def icp_levels(
    source_xyz: np.ndarray, target_xyz: columns.Target, init: np.ndarray, levels, options: Options, check, gap: float
):
    """(transform, fitness, RMSE of the last level) of coarse-to-fine ICP (:mod:`.icp`) or GICP of
    column surfaces; ``gap``: the target's spacing; search threads: ``options.threads`` (0: all)."""
    t, fit, rmse = init.copy(), 0.0, 0.0
    cache: dict[float, tuple] = {}
    cap = cap_voxel(source_xyz, MAX_ICP_POINTS)
    workers = options.threads if options.threads > 0 else -1
    gap = 1.5 * gap  # correspondences at least this far
    for voxel, dist, k in levels:
        voxel, dist = max(voxel, cap, gap / 1.5), max(dist, gap)  # no columns finer than the spacing
        if check:
            check()
        if voxel not in cache:
            src = columns.columns(source_xyz, voxel).xyz
            src = src[:: max(1, -(-len(src) // MAX_SOURCE_POINTS))]  # a fixed stride: spread, not density
            margin = 2.0 + dist  # the target's surface over the source's box under t, and this margin
            lo, hi = bounds(transform_points(source_xyz[:: max(1, len(source_xyz) // 20_000)], t), 2)
            tgt, normals = columns.column_surface(target_xyz, voxel, lo - margin, hi + margin)
            if len(tgt) < 3:
                raise SoilVolumeError(
                    "registration failed: the fine registration drifted off the before cloud "
                    "(no before points left under the after cloud); check that both clouds "
                    "cover the same site and their CRSs"
                )
            cache[voxel] = (src, tgt, normals, {})
        src, tgt, normals, kept = cache[voxel]  # kept: the voxel's k-d tree, or GICP's Open3D clouds
        if options.fine == "gicp":
            t, fit, rmse = _gicp(src, tgt, normals, dist, t, k, kept)
        else:
            if "tree" not in kept:
                kept["tree"] = tree_of(tgt)
            nearest = Nearest(tgt, dist, workers, tree=kept["tree"])
            res = icp.point_to_plane(src, tgt, normals, dist, t, k, ICP_TOL, ICP_ITER, workers, nearest)
            t, fit, rmse = res.transform, res.fitness, res.inlier_rmse
    return t, fit, rmse


def _gicp(src, tgt, normals, dist: float, t: np.ndarray, k: float, pcds: dict) -> tuple[np.ndarray, float, float]:
    """One level of Open3D's GICP (Tukey); the clouds kept in ``pcds`` for the next level."""
    reg = _o3d().pipelines.registration
    if "pcd" not in pcds:
        pcds["pcd"] = (to_pcd(src), to_pcd(tgt, normals))
    crit = reg.ICPConvergenceCriteria(relative_fitness=ICP_TOL, relative_rmse=ICP_TOL, max_iteration=ICP_ITER)
    est = reg.TransformationEstimationForGeneralizedICP(reg.TukeyLoss(k=k))
    res = reg.registration_generalized_icp(*pcds["pcd"], dist, t, est, crit)
    return np.asarray(res.transformation).copy(), float(res.fitness), float(res.inlier_rmse)
