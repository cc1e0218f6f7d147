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


def transform_points(xyz: np.ndarray, t: np.ndarray) -> np.ndarray:
    return xyz @ t[:3, :3].T + t[:3, 3]


def transform_points32(xyz: np.ndarray, t: np.ndarray, chunk: int = 4_000_000) -> np.ndarray:
    """A rigid transform of float32 local points, in chunks (no float64 copy of the cloud)."""
    out = np.empty_like(xyz, dtype=np.float32)
    r, s = t[:3, :3].T.astype(np.float32), t[:3, 3].astype(np.float32)
    for i in range(0, len(xyz), chunk):
        out[i : i + chunk] = xyz[i : i + chunk] @ r + s
    return out
