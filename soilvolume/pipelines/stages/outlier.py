"""filters.outlier: statistical (mean k-NN distance) or radius outliers are *classified* (7 by
default), not removed; a following ``filters.range`` with ``Classification![7:7]`` removes them."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .view import PointView, StageContext

OPTS = {"method", "mean_k", "multiplier", "min_k", "radius", "class", "threads"}
_CHUNK = 500_000


def mean_knn_distance(xyz: np.ndarray, k: int) -> np.ndarray:
    """Mean distance of every point to its k nearest neighbours (itself excluded, as PDAL drops
    the first of k+1 results). Queries run in the tree's spatial order, which is cache-friendly."""
    tree = cKDTree(xyz, balanced_tree=False, compact_nodes=False)
    order = tree.indices
    out = np.empty(xyz.shape[0], dtype=np.float64)
    kk = min(k + 1, xyz.shape[0])
    for s in range(0, xyz.shape[0], _CHUNK):
        sel = order[s : s + _CHUNK]
        d, _ = tree.query(xyz[sel], k=kk, workers=-1)
        d = d.reshape(d.shape[0], -1)
        out[sel] = d[:, 1:].mean(axis=1) if kk > 1 else 0.0
    return out


def outlier(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Statistical: outlier when mean k-NN distance >= mean + multiplier * std (sample std over
    all points). Radius: outlier unless more than ``min_k`` points (itself included) lie strictly
    within ``radius``. Leaves the view unchanged when every point would be an outlier."""
    method = (ctx.string(opts, "method", "statistical") or "").lower()
    label = ctx.integer(opts, "class", 7)
    cls = view.ensure("Classification")
    n = len(view)
    if n == 0:
        return view
    xyz = view.xyz
    if method == "statistical":
        k = ctx.integer(opts, "mean_k", 8)
        mult = ctx.number(opts, "multiplier", 2.0)
        if k < 1:
            raise ctx.error("option 'mean_k' must be >= 1")
        dist = mean_knn_distance(xyz, k)
        std = float(np.std(dist, ddof=1)) if n > 1 else 0.0
        bad = dist >= float(np.mean(dist)) + mult * std
    elif method == "radius":
        radius = ctx.positive(opts, "radius", 1.0)
        min_k = ctx.integer(opts, "min_k", 2)
        tree = cKDTree(xyz)
        counts = tree.query_ball_point(xyz, np.nextafter(radius, 0), workers=-1, return_length=True)
        bad = counts <= min_k
    else:
        raise ctx.error(f"option 'method' must be 'statistical' or 'radius', got {method!r}")
    if bad.all():
        return view
    cls[bad] = label
    view.meta["outliers"] = int(bad.sum())
    return view
