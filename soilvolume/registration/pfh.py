"""The paper's precise registration: PFH descriptors (Rusu 2008, not in Open3D: the Darboux angles of
every pair in a keypoint's neighbourhood, 5 x 5 x 5 bins) + SAC-IA (seeded, batched Kabsch on three
matched keypoints, Huber-scored, the winner refitted on its inliers) on a 6 m x 6 m patch."""

from __future__ import annotations

import numpy as np
import scipy

from .o3d import to_pcd, with_normals
from .rigid import transform_points

BINS = 5
VOXEL, MARGIN = 0.15, 3.0  # m: the patch's voxels; how much wider the target's patch is
SAC_ITER, K_SIM, INLIER = 3000, 4, 0.15  # SAC-IA hypotheses, similar descriptors drawn from, inlier distance (m)
MAX_ROTATION, MAX_SHIFT = 6.0, 4.0  # deg, m: hypotheses beyond are discarded


def pfh_features(xyz: np.ndarray, normals: np.ndarray, keys: np.ndarray, radius: float, k: int = 16) -> np.ndarray:
    """PFH histograms (len(keys), 125) of keypoints ``keys`` (indices into xyz)."""
    tree = scipy.spatial.cKDTree(xyz)
    dist, idx = tree.query(xyz[keys], k=k, distance_upper_bound=radius)
    valid = np.isfinite(dist)
    idx = np.where(valid, idx, keys[:, None])  # pad with the keypoint itself (zero-length pairs)
    a, b = np.triu_indices(k, 1)
    ps, pt = xyz[idx[:, a]], xyz[idx[:, b]]
    ns, nt = normals[idx[:, a]], normals[idx[:, b]]
    d = pt - ps
    dn = np.linalg.norm(d, axis=-1)
    ok = (dn > 1e-9) & valid[:, a] & valid[:, b]
    d = d / np.maximum(dn, 1e-9)[..., None]
    u = ns
    v = np.cross(d, u)
    v /= np.maximum(np.linalg.norm(v, axis=-1), 1e-12)[..., None]
    w = np.cross(u, v)
    alpha = np.einsum("...i,...i", v, nt)
    phi = np.einsum("...i,...i", u, d)
    theta = np.arctan2(np.einsum("...i,...i", w, nt), np.einsum("...i,...i", u, nt))
    fa = np.clip(((alpha + 1) / 2 * BINS).astype(int), 0, BINS - 1)
    fp = np.clip(((phi + 1) / 2 * BINS).astype(int), 0, BINS - 1)
    ft = np.clip(((theta + np.pi) / (2 * np.pi) * BINS).astype(int), 0, BINS - 1)
    code = (fa * BINS + fp) * BINS + ft
    rows = np.broadcast_to(np.arange(len(keys))[:, None], code.shape)
    hist = np.zeros((len(keys), BINS**3))
    np.add.at(hist, (rows[ok], code[ok]), 1.0)
    return hist / np.maximum(hist.sum(axis=1, keepdims=True), 1.0) * 100.0


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Batched rigid transforms (N, 4, 4) from (N, m, 3) point sets."""
    cs, cd = src.mean(axis=1, keepdims=True), dst.mean(axis=1, keepdims=True)
    h = np.einsum("nki,nkj->nij", src - cs, dst - cd)
    u, _, vt = np.linalg.svd(h)
    sign = np.sign(np.linalg.det(np.einsum("nij,njk->nik", vt.transpose(0, 2, 1), u.transpose(0, 2, 1))))
    dmat = np.tile(np.eye(3), (len(src), 1, 1))
    dmat[:, 2, 2] = sign
    r = np.einsum("nij,njk,nkl->nil", vt.transpose(0, 2, 1), dmat, u.transpose(0, 2, 1))
    t = np.eye(4)[None].repeat(len(src), axis=0)
    t[:, :3, :3] = r
    t[:, :3, 3] = cd[:, 0] - np.einsum("nij,nj->ni", r, cs[:, 0])
    return t


def choose_patch(source: np.ndarray, target: np.ndarray, size: float) -> np.ndarray:
    """Centre (x, y) of the ``size`` patch with the most relief that looks alike in both clouds."""
    lo, hi = source[:, :2].min(axis=0) + size, source[:, :2].max(axis=0) - size
    xs, ys = np.meshgrid(np.arange(lo[0], hi[0], size / 2), np.arange(lo[1], hi[1], size / 2))
    centres = np.c_[xs.ravel(), ys.ravel()]
    ts, tt = scipy.spatial.cKDTree(source[:, :2]), scipy.spatial.cKDTree(target[:, :2])
    best, score = centres[0] if len(centres) else source[:, :2].mean(axis=0), -np.inf
    for c in centres:
        zs = source[ts.query_ball_point(c, size / 2), 2]
        zt = target[tt.query_ball_point(c, size / 2), 2]
        if len(zs) < 50 or len(zt) < 50:
            continue
        s = min(zs.std(), zt.std()) - abs(zs.std() - zt.std()) * 2
        if s > score:
            best, score = c, s
    return best


def sac_ia(src: np.ndarray, fs: np.ndarray, tgt: np.ndarray, ft: np.ndarray, kt: np.ndarray, seed: int) -> np.ndarray:
    """SAC-IA of keypoints ``src`` (descriptors ``fs``) onto ``tgt`` (keypoints ``kt``, descriptors
    ``ft``): the best 4x4, hypotheses beyond :data:`MAX_ROTATION` deg or :data:`MAX_SHIFT` m discarded."""
    rng = np.random.default_rng(seed)
    _, sim = scipy.spatial.cKDTree(ft).query(fs, k=K_SIM)
    tree = scipy.spatial.cKDTree(tgt)
    best_t, best_err = np.eye(4), _score(tree, src, np.eye(4), INLIER)
    centre = src.mean(axis=0)
    cos_max = np.cos(np.radians(MAX_ROTATION))
    for start in range(0, SAC_ITER, 500):
        pick = rng.integers(0, len(src), size=(4 * min(500, SAC_ITER - start), 3))  # keypoint triples,
        p = src[pick]  # those at least 1 m apart kept (PCL's min_sample_distance)
        d = np.stack([np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in ((0, 1), (0, 2), (1, 2))], 1)
        pick = pick[(d >= 1.0).all(axis=1)][: min(500, SAC_ITER - start)]
        match = kt[sim[pick, rng.integers(0, K_SIM, size=pick.shape)]]
        ts = kabsch(src[pick], tgt[match])
        cos = (np.trace(ts[:, :3, :3], axis1=1, axis2=2) - 1) / 2
        moved = np.linalg.norm(ts[:, :3, :3] @ centre + ts[:, :3, 3] - centre, axis=1)
        for t in ts[(cos >= cos_max) & (moved <= MAX_SHIFT)]:
            err = _score(tree, src, t, INLIER)
            if err < best_err:
                best_t, best_err = t, err
    for _ in range(5):  # refit the winner on its inlier correspondences
        d, j = tree.query(transform_points(src, best_t))
        ok = d < INLIER
        if ok.sum() < 6:
            break
        best_t = kabsch(src[ok][None], tgt[j[ok]][None])[0]
    return best_t


def _score(tree: scipy.spatial.cKDTree, src: np.ndarray, t: np.ndarray, inlier: float) -> float:
    """Huber-truncated sum of distances of the transformed source keypoints to the target."""
    d, _ = tree.query(transform_points(src, t), distance_upper_bound=1.0)
    d = np.minimum(d, 1.0)
    return float(np.where(d < inlier, 0.5 * d * d, inlier * (d - 0.5 * inlier)).sum())


def pfh_sac_ia(source_xyz: np.ndarray, target_xyz: np.ndarray, init: np.ndarray, patch: float, seed: int) -> np.ndarray:
    """The paper's precise registration on a ``patch`` m square (the target's :data:`MARGIN` m wider),
    on :data:`VOXEL` m voxels: the 4x4 composed with ``init``."""
    src_all = transform_points(source_xyz, init)
    c = choose_patch(src_all, target_xyz, patch)
    h = patch / 2
    in_s = (np.abs(src_all[:, :2] - c) <= h).all(axis=1)
    in_t = (np.abs(target_xyz[:, :2] - c) <= h + MARGIN).all(axis=1)
    if in_s.sum() < 50 or in_t.sum() < 50:
        return init
    s = with_normals(to_pcd(src_all[in_s], voxel=VOXEL), 4 * VOXEL)
    t = with_normals(to_pcd(target_xyz[in_t], voxel=VOXEL), 4 * VOXEL)
    sp, sn = np.asarray(s.points), np.asarray(s.normals)
    tp, tn = np.asarray(t.points), np.asarray(t.normals)
    rng = np.random.default_rng(seed)
    ks = rng.choice(len(sp), min(600, len(sp)), replace=False)
    kt = rng.choice(len(tp), min(2500, len(tp)), replace=False)
    fs, ft = pfh_features(sp, sn, ks, 5 * VOXEL), pfh_features(tp, tn, kt, 5 * VOXEL)
    return sac_ia(sp[ks], fs, tp, ft, kt, seed) @ init
