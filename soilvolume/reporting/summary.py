"""Plain-language figures shared by report.html and QGIS: the registration as rotation and shift,
and whether the net change is significant."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def rotation_shift(transform_local: Any) -> dict[str, float]:
    """Rotation (°, about any axis), its tilt and yaw, and the shift (m: horizontal, vertical, total)
    of a local 4x4 (the origin is inside the data, so the shift is where the data is)."""
    t = np.asarray(transform_local, dtype=float)
    r, s = t[:3, :3], t[:3, 3]
    cos_angle = float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))
    return {
        "rotation_deg": math.degrees(math.acos(cos_angle)),
        "tilt_deg": math.degrees(math.acos(float(np.clip(r[2, 2], -1.0, 1.0)))),
        "yaw_deg": math.degrees(math.atan2(r[1, 0], r[0, 0])),
        "shift_m": float(np.linalg.norm(s)),
        "shift_horizontal_m": float(np.hypot(s[0], s[1])),
        "shift_vertical_m": float(s[2]),
        "dx_m": float(s[0]),
        "dy_m": float(s[1]),
    }


def significance(report: dict[str, Any]) -> str:
    """One sentence: is the net change distinguishable from zero at the run's confidence? None
    is stated for a run whose verdict is *not reliable* (its interval cannot be relied on)."""
    net = report.get("volume_m3", {}).get("net")
    unc = report.get("uncertainty_m3", {})
    half, conf = unc.get("net"), unc.get("confidence", 0.95)
    if net is None or half is None:
        return "No uncertainty could be estimated, so the significance of the change is unknown."
    level = f"{conf * 100:g} %"
    if str((report.get("quality") or {}).get("verdict") or "") == "not reliable":
        return (
            f"The run is not reliable (see the quality verdict's reasons): the net change of {net:+,.1f} m³ "
            f"± {half:,.1f} m³ carries no statement of confidence, neither of a gain nor of a loss."
        )
    if abs(net) > half:
        kind = "gain (fill)" if net > 0 else "loss (cut)"
        return (
            f"The net change of {net:+,.1f} m³ ± {half:,.1f} m³ is a significant {kind} "
            f"at {level} confidence: the interval does not include zero."
        )
    return (
        f"The net change of {net:+,.1f} m³ ± {half:,.1f} m³ is not significant at {level} "
        f"confidence: the interval includes zero, so no net gain or loss is shown."
    )


def quality(report: dict[str, Any]) -> dict[str, Any]:
    """The run's quality verdict (reliable / use with caution / not reliable) and its plain
    sentences; an empty verdict when the engine gave none."""
    q = report.get("quality") or {}
    return {
        "verdict": str(q.get("verdict") or ""),
        "trusted": q.get("trusted"),
        "messages": [str(m) for m in q.get("messages") or []],
    }
