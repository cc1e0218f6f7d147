"""Coarse (FPFH + RANSAC on column surfaces, within the GPS prior) and fine (:mod:`.fine`) registration
of the after cloud onto the before cloud, local frame; each stage a
:class:`~soilvolume.core.types.StageQuality` (transform, fitness, RMSE)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..core.record import Georeferencing
from ..core.types import SoilVolumeError, StageQuality
from ..options import Options
from . import columns
from .fine import fine_stage
from .ground import EVAL_DISTANCE, cap_voxel, evaluate_surface, judged, spacing
from .o3d import _o3d, limit_threads, one_thread, to_pcd
from .rigid import rotation_deg, shift_at

AUTO_FITNESS = 0.6  # --coarse auto runs FPFH only when the fine stage from the GPS pose fits worse
MAX_COARSE_POINTS = 15_000
COARSE_ITER = 20_000  # RANSAC iterations of the coarse stage
NAN = float("nan")


@dataclass(frozen=True)
class Registration:
    """The accepted transform (after -> before), each stage's quality, the georeferencing trust."""

    transform: np.ndarray
    coarse: StageQuality
    fine: StageQuality
    georeferencing: Georeferencing | None = None


def register(
    after_xyz: np.ndarray,
    before_xyz: np.ndarray,
    options: Options,
    check: Callable[[], None] | None = None,
    dense: tuple[np.ndarray, np.ndarray] | None = None,
    precise: bool = False,
) -> Registration:
    """Register after onto before (local, thinned; before cropped to the after footprint + radius).
    ``dense``: the full-resolution (after, before) clouds, for the paper's PFH."""
    eye = np.eye(4)
    if precise:
        gap = spacing(before_xyz)
        fit, rmse = evaluate_surface(judged(after_xyz, gap), before_xyz, eye, gap)
        skipped = "skipped: coordinates used as georeferenced ({opt:georeferencing})"
        coarse = StageQuality("none", NAN, NAN, accepted=False, note=skipped)
        return Registration(eye, coarse, StageQuality("none", fit, rmse, note=skipped))
    limit_threads(options.threads)
    target = columns.Cloud(before_xyz)  # the fine stage's many boxes on the before cloud share its cuts
    if options.coarse == "auto" and options.fine != "none":
        first = fine_stage(after_xyz, target, [(eye, "gps")], options, check, dense)
        if first.fitness >= AUTO_FITNESS:  # the GPS pose converged: FPFH cannot do better here
            note = (
                f"skipped: the fine registration from the GPS pose fits ({first.fitness:.0%} of the "
                f"after cloud within {EVAL_DISTANCE} m); {{opt:coarse=fpfh}} forces it"
            )
            return Registration(
                first.transform, StageQuality("fpfh-ransac", NAN, NAN, accepted=False, note=note), first
            )
    coarse = coarse_stage(after_xyz, before_xyz, options)
    starts = [(eye, "gps")]
    if coarse.accepted and not np.allclose(coarse.transform, eye):
        starts.append((coarse.transform, "coarse"))
    best = fine_stage(after_xyz, target, starts, options, check, dense)
    if options.coarse == "auto" and coarse.accepted and "gps" in best.note:
        note = coarse.note + "; rejected: fine registration fits better from the GPS pose"
        coarse = replace(coarse, accepted=False, note=note)
    if best.fitness < 0.2:
        raise SoilVolumeError(
            f"registration failed: only {best.fitness:.0%} of the after cloud lies within "
            f"{EVAL_DISTANCE} m of the before surface (RMSE {best.rmse:.3f} m); check that both "
            "clouds cover the same site and their CRSs"
        )
    return Registration(best.transform, coarse, best)


def coarse_stage(after_xyz, before_xyz, options: Options) -> StageQuality:
    """``--coarse``: FPFH features + RANSAC of the column surfaces on a coarse voxel (seeded), accepted
    within the GPS prior (or forced by ``fpfh``)."""
    t0 = time.perf_counter()
    if options.coarse == "none":
        return StageQuality("none", NAN, NAN, accepted=False, note="skipped")
    o3d = _o3d()
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(options.seed)
    voxel = max(options.coarse_voxel, cap_voxel(after_xyz, MAX_COARSE_POINTS), cap_voxel(before_xyz, MAX_COARSE_POINTS))
    src, tgt = (to_pcd(*columns.column_surface(xyz, voxel)) for xyz in (after_xyz, before_xyz))
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    fs, ft = reg.compute_fpfh_feature(src, param), reg.compute_fpfh_feature(tgt, param)
    dist = 1.5 * voxel
    checkers = [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)]
    with one_thread():  # the same pose from the same inputs, however busy the machine
        res = reg.registration_ransac_based_on_feature_matching(
            src,
            tgt,
            fs,
            ft,
            True,
            dist,
            reg.TransformationEstimationPointToPoint(False),
            3,
            checkers,
            reg.RANSACConvergenceCriteria(COARSE_ITER, 0.999),
        )
    t = np.asarray(res.transformation)
    src, tgt = to_pcd(after_xyz, voxel=options.coarse_voxel), to_pcd(before_xyz, voxel=options.coarse_voxel)
    ev = reg.evaluate_registration(src, tgt, 1.5 * options.coarse_voxel, t)  # point to point
    rot, shift = rotation_deg(t), shift_at(t, after_xyz.mean(axis=0))
    within = rot <= options.max_gps_rotation and shift <= options.max_gps_shift
    accepted = options.coarse == "fpfh" or within
    note = f"FPFH+RANSAC moved the after centre {shift:.2f} m and rotated {rot:.2f} deg"
    if not within:
        note += f"; outside the GPS error prior ({options.max_gps_shift} m, {options.max_gps_rotation} deg)" + (
            "" if accepted else ": rejected"
        )
    fit, rmse = float(ev.fitness), float(ev.inlier_rmse)
    return StageQuality("fpfh-ransac", fit, rmse, t, accepted, time.perf_counter() - t0, note)
