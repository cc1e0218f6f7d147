"""A small COPC writer for the tests (copclib): a two-level octree, a thinned root node and the
rest split by octant, so bounded and resolution-limited reads have nodes to skip."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_copc(
    path: Path,
    xyz: np.ndarray,
    cls: np.ndarray | None = None,
    crs_wkt: str = "",
    scale: float = 0.001,
    seed: int = 0,
    spacing: float | None = None,
) -> Path:
    import copclib as c
    import laspy

    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    off = np.floor(lo)
    writer = c.FileWriter(str(path), c.CopcConfigWriter(6, c.Vector3(scale, scale, scale), c.Vector3(*off), crs_wkt))
    writer.copc_config.las_header.min = c.Vector3(*lo)
    writer.copc_config.las_header.max = c.Vector3(*hi)
    half, centre = float((hi - lo).max() / 2) + 1.0, (lo + hi) / 2
    info = writer.copc_config.copc_info
    info.center_x, info.center_y, info.center_z = map(float, centre)
    info.halfsize, info.spacing = half, spacing or 2 * half / 64  # the root level's point spacing
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.full(3, scale), off

    def node(key: tuple, idx: np.ndarray) -> None:
        rec = laspy.ScaleAwarePointRecord.zeros(len(idx), header=header)
        rec.x, rec.y, rec.z = xyz[idx, 0], xyz[idx, 1], xyz[idx, 2]
        if cls is not None:
            rec.classification = cls[idx]
        writer.AddNode(c.VoxelKey(*key), c.VectorChar(memoryview(rec.array.view(np.int8).reshape(-1))))

    order = np.random.default_rng(seed).permutation(len(xyz))
    top, rest = order[: len(xyz) // 16], order[len(xyz) // 16 :]
    node((0, 0, 0, 0), top)
    octant = ((xyz[rest] - (centre - half)) // half).astype(int)
    for key in sorted({tuple(v) for v in octant}):
        node((1, *key), rest[(octant == key).all(axis=1)])
    writer.Close()
    return path
