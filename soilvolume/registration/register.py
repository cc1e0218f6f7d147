"""Coarse (FPFH + RANSAC) and fine (robust point-to-plane ICP, GICP, or the paper's PFH + SAC-IA)
registration of the after cloud onto the before cloud, in local coordinates.

Every stage returns a :class:`~soilvolume.core.types.StageQuality` carrying its 4x4 transform (after
-> before, local frame), fitness and inlier RMSE, as Open3D's registration pipelines do.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..core.cells import bounds
from ..core.record import Georeferencing
from ..core.types import SoilVolumeError, StageQuality
from ..options import Options
from . import columns, icp
from .ground import margin_points, spacing, stable_source
from .o3d import _o3d, limit_threads, to_pcd
from .rigid import rotation_deg, shift_at, tilt_deg, transform_points

# (voxel m, max correspondence distance m, Tukey k m): coarse-to-fine, shrinking distances.
ICP_LEVELS = ((1.0, 6.0, 3.0), (1.0, 3.0, 1.0), (0.5, 1.5, 0.5), (0.25, 0.8, 0.25), (0.25, 0.4, 0.15))
REFINE_LEVELS = ((0.5, 0.8, 0.25), (0.25, 0.4, 0.12))
EVAL_DISTANCE = 0.4
AUTO_FITNESS = 0.6  # --coarse auto runs FPFH only when the fine stage from the GPS pose fits worse
MAX_ICP_POINTS = 150_000  # per level: coarser voxels on very large sites
MAX_COARSE_POINTS = 15_000
MAX_SOURCE_POINTS = 30_000  # ICP source points per level (the target keeps its density)
ICP_TOL, ICP_ITER = 1e-6, 30
COARSE_ITER = 20_000  # RANSAC iterations of the coarse stage
STABLE_PASSES = 1  # refinements on the stable ground found at the current pose


@dataclass(frozen=True)
class Registration:
    """The accepted transform (after -> before, local frame), each stage's quality and how far
    the georeferencing was trusted (filled in by :func:`soilvolume.workflow.steps.register_pair`)."""

    transform: np.ndarray
    coarse: StageQuality
    fine: StageQuality
    georeferencing: Georeferencing | None = None


def within_prior(t: np.ndarray, centre: np.ndarray, options: Options) -> bool:
    """Whether a pose stays within the georeferencing prior (shift at the after centre, rotation
    and tilt)."""
    return (
        shift_at(t, centre) <= options.max_gps_shift
        and rotation_deg(t) <= options.max_gps_rotation
        and tilt_deg(t) <= options.max_gps_tilt
    )


def evaluate(source, target, t: np.ndarray, distance: float = EVAL_DISTANCE) -> tuple[float, float]:
    """(fitness, inlier RMSE) of ``t`` at ``distance`` (Open3D, point to point)."""
    o3d = _o3d()
    ev = o3d.pipelines.registration.evaluate_registration(source, target, distance, t)
    return float(ev.fitness), float(ev.inlier_rmse)


def finest_column(after_xyz: np.ndarray, gap: float) -> float:
    """The side (m) of the finest columns the fine registration matches surfaces on (its last
    level's voxel, no finer than the target's point spacing ``gap`` nor coarser than the cap on
    large clouds): it cannot place the after survey more finely than this horizontally."""
    return max(ICP_LEVELS[-1][0], gap, _cap_voxel(after_xyz, MAX_ICP_POINTS))


def _cap_voxel(xyz: np.ndarray, max_points: int) -> float:
    """The voxel size that leaves about ``max_points`` of a cloud (0 when it has fewer)."""
    if len(xyz) <= max_points:
        return 0.0
    return spacing(xyz) * float(np.sqrt(len(xyz) / max_points))


def evaluate_surface(
    source_xyz: np.ndarray,
    target_xyz: columns.Target,
    t: np.ndarray,
    distance: float = EVAL_DISTANCE,
    gap: float | None = None,
) -> tuple[float, float]:
    """(fitness, RMSE) on terrain: the fraction of source points within ``distance`` of the
    tangent plane of the target surface (columns of max(0.25 m, 2 point spacings)), and the RMS
    of those distances. Meaningful on sparse clouds, unlike point-to-point. ``target_xyz``: an
    array or a :class:`~soilvolume.registration.columns.Cloud` (its cuts remembered)."""
    src = transform_points(source_xyz[:: max(1, len(source_xyz) // 100_000)], t)
    gap = spacing(columns.Cloud.points(target_xyz)) if gap is None else gap
    lo, hi = bounds(src, 2)
    cols = columns.columns(target_xyz, max(0.25, 2 * gap), lo - 1.0, hi + 1.0)
    if len(cols.xyz) == 0:
        return 0.0, float("nan")
    r = np.abs(columns.plane_residuals(src, cols, columns.normals(cols)))
    ok = r <= distance
    fit = float(ok.sum() / max(len(src), 1))
    return fit, float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else float("nan")


def coarse_fpfh(source_xyz: np.ndarray, target_xyz: np.ndarray, voxel: float, seed: int) -> np.ndarray:
    """FPFH features + RANSAC on a coarse voxel (seeded); returns the 4x4 transform."""
    o3d = _o3d()
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(seed)
    voxel = max(voxel, _cap_voxel(source_xyz, MAX_COARSE_POINTS), _cap_voxel(target_xyz, MAX_COARSE_POINTS))
    src, tgt = _column_pcd(source_xyz, voxel), _column_pcd(target_xyz, voxel)
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


def _column_pcd(xyz: columns.Target, voxel: float, lo: np.ndarray | None = None, hi: np.ndarray | None = None):
    """Open3D cloud of the column means of ``xyz`` (within lo..hi) with surface normals."""
    return _as_pcd(*_column_surface(xyz, voxel, lo, hi))


def _column_surface(
    xyz: columns.Target, voxel: float, lo: np.ndarray | None = None, hi: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The column means of ``xyz`` (within lo..hi) and their surface normals."""
    cols = columns.columns(xyz, voxel, lo, hi)
    return cols.xyz, columns.normals(cols)


def _as_pcd(xyz: np.ndarray, normals: np.ndarray | None = None):
    """An Open3D cloud of points (and normals)."""
    pcd = to_pcd(xyz)
    if normals is not None:
        pcd.normals = _o3d().utility.Vector3dVector(normals)
    return pcd


def icp_levels(
    source_xyz: np.ndarray,
    target_xyz: columns.Target,
    init: np.ndarray,
    levels=ICP_LEVELS,
    method: str = "icp",
    check: Callable[[], None] | None = None,
    scores: bool = False,
    gap: float | None = None,
    workers: int = -1,
):
    """Robust coarse-to-fine ICP (point-to-plane with a Tukey kernel, :mod:`.icp`, or Open3D's
    GICP) of column-mean surfaces (target normals from the column heights); with ``scores``
    returns (transform, fitness, inlier RMSE) of the last level. ``gap``: the target's point
    spacing; ``target_xyz``: an array or a :class:`~soilvolume.registration.columns.Cloud`;
    ``workers``: the nearest-neighbour searches' threads (-1: all cores)."""
    t, fit, rmse = init.copy(), 0.0, 0.0
    cache: dict[float, tuple] = {}
    cap = _cap_voxel(source_xyz, MAX_ICP_POINTS)
    gap = 1.5 * (spacing(columns.Cloud.points(target_xyz)) if gap is None else gap)  # correspondences at least this far
    for voxel, dist, k in levels:
        voxel, dist = max(voxel, cap, gap / 1.5), max(dist, gap)  # no columns finer than the spacing
        if check:
            check()
        if voxel not in cache:
            src = _sampled(columns.columns(source_xyz, voxel).xyz, MAX_SOURCE_POINTS)
            cache[voxel] = (src, *_surface(target_xyz, source_xyz, t, voxel, 2.0 + dist), {})
        src, tgt, normals, kept = cache[voxel]  # kept: the voxel's k-d tree, or GICP's Open3D clouds
        if method == "gicp":
            t, fit, rmse = _gicp(src, tgt, normals, dist, t, k, kept)
        else:
            if "tree" not in kept:
                kept["tree"] = icp.tree_of(tgt)
            nearest = icp.Nearest(tgt, dist, workers, tree=kept["tree"])
            res = icp.point_to_plane(src, tgt, normals, dist, t, k, ICP_TOL, ICP_ITER, workers, nearest)
            t, fit, rmse = res.transform, res.fitness, res.inlier_rmse
    return (t, fit, rmse) if scores else t


def _gicp(src, tgt, normals, dist: float, t: np.ndarray, k: float, pcds: dict) -> tuple[np.ndarray, float, float]:
    """One level of Open3D's generalized ICP (Tukey kernel) of arrays; their Open3D clouds are
    kept in ``pcds`` for the next level on the same voxel."""
    reg = _o3d().pipelines.registration
    if "pcd" not in pcds:
        pcds["pcd"] = (_as_pcd(src), _as_pcd(tgt, normals))
    crit = reg.ICPConvergenceCriteria(relative_fitness=ICP_TOL, relative_rmse=ICP_TOL, max_iteration=ICP_ITER)
    est = reg.TransformationEstimationForGeneralizedICP(reg.TukeyLoss(k=k))
    res = reg.registration_generalized_icp(*pcds["pcd"], dist, t, est, crit)
    return np.asarray(res.transformation).copy(), float(res.fitness), float(res.inlier_rmse)


def _surface(target_xyz: columns.Target, source_xyz: np.ndarray, t: np.ndarray, voxel: float, margin: float):
    """The target's column surface and normals over the source's box under ``t`` + margin."""
    lo, hi = bounds(transform_points(source_xyz[:: max(1, len(source_xyz) // 20_000)], t), 2)
    xyz, normals = _column_surface(target_xyz, voxel, lo - margin, hi + margin)
    if len(xyz) < 3:
        raise SoilVolumeError(
            "registration failed: the fine registration drifted off the before cloud "
            "(no before points left under the after cloud); check that both clouds "
            "cover the same site and their CRSs"
        )
    return xyz, normals


def _sampled(xyz: np.ndarray, cap: int) -> np.ndarray:
    """At most ``cap`` points of a cloud, a fixed-stride sample (deterministic): the source side
    of ICP needs well-spread points, not all of them; the target keeps its density."""
    n = len(xyz)
    if n <= cap:
        return xyz
    return xyz[:: int(np.ceil(n / cap))]


def register(
    after_xyz: np.ndarray,
    before_xyz: np.ndarray,
    options: Options,
    check: Callable[[], None] | None = None,
    dense: tuple[np.ndarray, np.ndarray] | None = None,
    precise: bool = False,
) -> Registration:
    """Register after onto before (both local, typically the thinned subsets; ``before_xyz`` is
    the before cloud cropped to the after footprint + radius). ``dense``: the full-resolution
    (after, before) clouds, for the paper's PFH patch matching."""
    eye = np.eye(4)
    if precise:
        fit, rmse = evaluate_surface(_judged(after_xyz, spacing(before_xyz)), before_xyz, eye)
        skipped = "skipped: coordinates used as georeferenced ({opt:georeferencing})"
        return Registration(
            eye,
            StageQuality("none", float("nan"), float("nan"), eye, False, 0.0, skipped),
            StageQuality("none", fit, rmse, eye, True, 0.0, skipped),
        )
    limit_threads(options.threads)
    target = columns.Cloud(before_xyz)  # the fine stage's many boxes on the before cloud share its cuts
    if options.coarse == "auto" and options.fine != "none":
        first = _fine_stage(after_xyz, target, [(eye, "gps")], options, check, dense)
        if first.fitness >= AUTO_FITNESS:  # the GPS pose converged: FPFH cannot do better here
            note = (
                f"skipped: the fine registration from the GPS pose fits ({first.fitness:.0%} of the "
                f"after cloud within {EVAL_DISTANCE} m); {{opt:coarse=fpfh}} forces it"
            )
            return Registration(
                first.transform, StageQuality("fpfh-ransac", float("nan"), float("nan"), eye, False, 0.0, note), first
            )
    coarse = _coarse_stage(after_xyz, before_xyz, options)
    starts = [(eye, "gps")]
    if coarse.accepted and not np.allclose(coarse.transform, eye):
        starts.append((coarse.transform, "coarse"))
    best = _fine_stage(after_xyz, target, starts, options, check, dense)
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


def _better(a: StageQuality, b: StageQuality) -> bool:
    if abs(a.fitness - b.fitness) > 0.005:
        return a.fitness > b.fitness
    return a.rmse < b.rmse


def _coarse_stage(after_xyz, before_xyz, options: Options) -> StageQuality:
    t0 = time.perf_counter()
    if options.coarse == "none":
        return StageQuality("none", float("nan"), float("nan"), np.eye(4), False, 0.0, "skipped")
    t = coarse_fpfh(after_xyz, before_xyz, options.coarse_voxel, options.seed)
    src, tgt = to_pcd(after_xyz, options.coarse_voxel), to_pcd(before_xyz, options.coarse_voxel)
    fit, rmse = evaluate(src, tgt, t, 1.5 * options.coarse_voxel)
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


def _fine_stage(after_xyz, before_xyz, starts, options: Options, check, dense=None) -> StageQuality:
    """The fine stage from the best of the starting poses: ICP/GICP run their first (1 m) levels
    from each start and finish from the one that fits best; PFH and none are scored whole.
    ``before_xyz``: an array or a :class:`~soilvolume.registration.columns.Cloud`."""
    t0 = time.perf_counter()
    gap = spacing(columns.Cloud.points(before_xyz))
    judge = _judged(after_xyz, gap)
    if options.fine in ("icp", "gicp"):
        (t, label, rejected, (fit, rmse)), alt, refined = _icp_from_best(
            judge, after_xyz, before_xyz, starts, options, check, gap
        )
        return StageQuality(
            options.fine,
            fit,
            rmse,
            t,
            True,
            time.perf_counter() - t0,
            f"started from the {label} pose",
            alternative=alt,
            beyond_prior=rejected,
            poses=refined,
        )
    best: StageQuality | None = None
    for init, label in starts:
        if options.fine == "pfh":
            from .pfh import pfh_sac_ia

            src, tgt = dense if dense is not None else (after_xyz, columns.Cloud.points(before_xyz))
            t = pfh_sac_ia(src, tgt, init, options.pfh_patch, options.seed)
        else:
            t = init
        fit, rmse = evaluate_surface(judge, before_xyz, t, gap=gap)
        q = StageQuality(options.fine, fit, rmse, t, True, 0.0, f"started from the {label} pose")
        if best is None or _better(q, best):
            best = q
    assert best is not None
    return replace(best, seconds=time.perf_counter() - t0)


def _icp_from_best(src, after_xyz, before_xyz, starts, options: Options, check, gap: float):
    """ICP from the best start on the margin of the after survey (``src``: :func:`_judged`), then
    refined twice on the stable ground found at the pose reached (works inside the survey never
    pull the pose); the pose that fits the margin best within the georeferencing prior wins.
    Returns ((transform, label, poses rejected beyond the prior, its (fitness, RMSE) on the
    margin), the other refined pose (margin-only or stable-ground ICP) as an alternative for the
    uncertainty, None when there is none, and every refined pose, those beyond the prior too)."""
    method, workers = options.fine, options.threads if options.threads > 0 else -1
    head, tail = ICP_LEVELS[:2], ICP_LEVELS[2:]
    scored = []
    for init, label in starts:
        t, fit, rmse = icp_levels(src, before_xyz, init, head, method, check, True, gap, workers)
        scored.append((-fit, rmse, label, t))
    _, _, label, t = min(scored, key=lambda s: (round(s[0], 3), s[1]))
    t = icp_levels(src, before_xyz, t, tail, method, check, gap=gap, workers=workers)
    poses = [(init, lab) for init, lab in starts] + [(t, label)]
    for _ in range(STABLE_PASSES):
        src_stable = stable_source(after_xyz, before_xyz, t, gap=gap)
        if len(src_stable) <= 100:
            break
        # src_stable is already in the before frame: refine a correction on top of t.
        dt = icp_levels(src_stable, before_xyz, np.eye(4), REFINE_LEVELS, method, check, gap=gap, workers=workers)
        t = dt @ t
        poses.append((t, label))
    centre = after_xyz.mean(axis=0)
    allowed = [p for p in poses if within_prior(p[0], centre, options)] or poses[:1]
    best, scores = _best_on(src, before_xyz, allowed, gap)
    others = [p[0] for p in allowed[len(starts) :] if p[0] is not best[0]]
    rejected = len(poses) - len(allowed)
    label = best[1] + (f"; {rejected} pose(s) beyond the georeferencing prior rejected" if rejected else "")
    refined = tuple(p[0] for p in poses[len(starts) :])
    return (best[0], label, rejected, scores), (others[-1] if others else None), refined


def _judged(after_xyz: np.ndarray, gap: float) -> np.ndarray:
    """The after points a pose is judged on: the margin of the after survey (works inside it do
    not fit any correct pose), or all points when the margin is too thin to judge."""
    ring = margin_points(after_xyz, gap)
    return ring if len(ring) >= max(500, 0.05 * len(after_xyz)) else after_xyz


def _best_on(src, before_xyz, poses, gap: float) -> tuple[tuple[np.ndarray, str], tuple[float, float]]:
    """The pose under which the margin points fit the before surface best (the last, most
    refined one on ties): a pass that drifted never replaces a better pose; and its (fitness,
    RMSE) there (:func:`evaluate_surface`)."""
    best, best_key, scores = poses[-1], None, (float("nan"), float("nan"))
    for k, (t, label) in enumerate(poses):
        fit, rmse = evaluate_surface(src, before_xyz, t, gap=gap)
        key = (round(fit, 2), -np.nan_to_num(rmse, nan=1e9), k)
        if best_key is None or key > best_key:
            best, best_key, scores = (t, label), key, (fit, rmse)
    return best, scores
