"""Rigid 4x4 transforms: applying them to points and describing them (rotation, tilt, shift)."""

from __future__ import annotations

import numpy as np


def rotation_deg(t: np.ndarray) -> float:
    """Rotation angle (degrees) of a 4x4 rigid transform."""
    c = (np.trace(t[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def tilt_deg(t: np.ndarray) -> float:
    """Tilt (degrees) of a 4x4 rigid transform: the angle it turns the vertical by."""
    return float(np.degrees(np.arccos(np.clip(t[2, 2], -1.0, 1.0))))


def shift_at(t: np.ndarray, point: np.ndarray) -> float:
    """How far the transform moves ``point`` (metres)."""
    return float(np.linalg.norm(t[:3, :3] @ point + t[:3, 3] - point))


def rotation_zyx(rx: float, ry: float, rz: float) -> np.ndarray:
    """``Rz Ry Rx``: the rotation by ``rx``, then ``ry``, then ``rz`` radians about x, y and z."""
    ca, sa = np.cos(rx), np.sin(rx)
    cb, sb = np.cos(ry), np.sin(ry)
    cc, sc = np.cos(rz), np.sin(rz)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    rot_y = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rot_z = np.array([[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]])
    return rot_z @ rot_y @ rot_x


def transform_points(xyz: np.ndarray, t: np.ndarray) -> np.ndarray:
    return xyz @ t[:3, :3].T + t[:3, 3]


def transform_points32(xyz: np.ndarray, t: np.ndarray, chunk: int = 4_000_000) -> np.ndarray:
    """``xyz @ R.T + shift`` of float32 points in float32, in chunks (no float64 copy): as ``R @ xyz.T``
    (same bits, 3-6x faster in BLAS), returned transposed. A lone last point joins the chunk before
    it (a matrix-vector product would round otherwise)."""
    out = np.empty((3, len(xyz)), np.float32)
    r, s = t[:3, :3].astype(np.float32), t[:3, 3].astype(np.float32)
    n = len(xyz)
    starts = list(range(0, n, chunk))
    if len(starts) > 1 and n - starts[-1] == 1:
        starts.pop()
    for i, j in zip(starts, [*starts[1:], n][: len(starts)], strict=True):  # (no points: no chunk)
        np.matmul(r, xyz[i:j].T, out=out[:, i:j])
    out += s[:, None]
    return out.T
