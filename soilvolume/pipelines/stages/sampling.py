"""Thinning: filters.voxelcenternearestneighbor and filters.sample (Poisson dart throwing)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ...core.cells import cell_index
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
    idx = cell_index(xyz, lo, cell)
    centre = lo + (idx + 0.5) * cell
    dist = ((centre - xyz) ** 2).sum(axis=1)
    span = idx.max(axis=0) + 1
    key = (idx[:, 1] * span[0] + idx[:, 0]) * span[2] + idx[:, 2]  # (y, x, z) voxel order
    order = np.lexsort((dist, key))  # stable: the first point wins ties
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    return view.take(order[first])


def sample(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Keep a point unless an already kept point (in input order) lies closer than ``radius``;
    ``cell`` instead gives radius = cell * sqrt(3) / 2. Exactly one of the two is required."""
    if ("cell" in opts) == ("radius" in opts):
        raise ctx.error("set exactly one of 'cell' or 'radius'")
    radius = ctx.positive(opts, "radius") if "radius" in opts else ctx.positive(opts, "cell") * np.sqrt(3.0) / 2.0
    n = len(view)
    if n == 0:
        return view
    xyz = view.xyz
    r_strict = float(np.nextafter(radius, 0))
    keep = np.zeros(n, dtype=bool)
    for s in range(0, n, _CHUNK):
        e = min(n, s + _CHUNK)
        cand = np.arange(s, e)
        if keep[:s].any():  # drop points near anything kept in earlier chunks
            kept_tree = cKDTree(xyz[:s][keep[:s]])
            d, _ = kept_tree.query(xyz[s:e], k=1, distance_upper_bound=r_strict, workers=-1)
            cand = cand[~(d < radius)]
        if cand.size == 0:
            continue
        # the rest, in input order: a point is kept unless an earlier kept one is too close
        pairs = cKDTree(xyz[cand]).query_pairs(r_strict, output_type="ndarray")
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if len(pairs) else pairs
        ptr = np.searchsorted(pairs[:, 0], np.arange(cand.size + 1)).tolist()
        later = pairs[:, 1].tolist()
        taken = bytearray(cand.size)
        for a in range(cand.size):
            if not taken[a]:
                keep[cand[a]] = True
                for b in later[ptr[a] : ptr[a + 1]]:
                    taken[b] = 1
    return view.take(keep)
