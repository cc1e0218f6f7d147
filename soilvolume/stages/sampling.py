"""Thinning: filters.voxelcenternearestneighbor and filters.sample (Poisson dart throwing)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .view import PointView, StageContext

VOXEL_OPTS = {"cell"}
SAMPLE_OPTS = {"cell", "radius"}
_CHUNK = 200_000


def voxel_center_nn(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """One point per occupied voxel (voxels of edge ``cell`` from the points' minimum corner): the
    point nearest the voxel centre (first on ties), output ordered by (y, x, z) voxel index."""
    cell = ctx.positive(opts, "cell", 1.0)
    if len(view) == 0:
        return view
    xyz = view.xyz
    lo = xyz.min(axis=0)
    idx = np.floor((xyz - lo) / cell).astype(np.int64)
    centre = lo + (idx + 0.5) * cell
    dist = ((centre - xyz) ** 2).sum(axis=1)
    c, r, d = idx[:, 0], idx[:, 1], idx[:, 2]
    order = np.lexsort((np.arange(len(view)), dist, d, c, r))
    key = idx[order][:, [1, 0, 2]]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (key[1:] != key[:-1]).any(axis=1)
    return view.take(order[first])


def sample(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Keep a point unless an already kept point (in input order) lies closer than ``radius``;
    ``cell`` instead gives radius = cell * sqrt(3) / 2. Exactly one of the two is required."""
    if ("cell" in opts) == ("radius" in opts):
        raise ctx.error("set exactly one of 'cell' or 'radius'")
    radius = (ctx.positive(opts, "radius") if "radius" in opts
              else ctx.positive(opts, "cell") * np.sqrt(3.0) / 2.0)
    n = len(view)
    if n == 0:
        return view
    xyz = view.xyz
    tree = cKDTree(xyz)
    r_strict = np.nextafter(radius, 0)
    taken = np.zeros(n, dtype=bool)
    keep = np.zeros(n, dtype=bool)
    for s in range(0, n, _CHUNK):
        e = min(n, s + _CHUNK)
        near = tree.query_ball_point(xyz[s:e], r_strict, workers=-1)
        for i in range(s, e):
            if not taken[i]:
                keep[i] = True
                taken[near[i - s]] = True
    return view.take(keep)
