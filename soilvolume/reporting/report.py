"""report.json: built from the run's numbers (the single source for CLI, QGIS and HTML)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import StageQuality
from ..inputs.io import atomic_path


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return _clean(v.tolist())
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def stage_dict(q: StageQuality) -> dict:
    return {"method": q.method, "fitness": q.fitness, "rmse": q.rmse, "accepted": q.accepted,
            "seconds": q.seconds, "note": q.note, "transform_local": q.transform}


def absolute_transform(t_local: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The local-frame transform expressed on absolute coordinates: S(o) T S(-o)."""
    s, s_inv = np.eye(4), np.eye(4)
    s[:3, 3], s_inv[:3, 3] = origin, -origin
    return s @ t_local @ s_inv


def write_json(path: Path, report: dict) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(_clean(report), indent=2))


def summary_lines(report: dict) -> list[str]:
    """A few human lines for the terminal."""
    v, u = report["volume_m3"], report["volume_uncompensated_m3"]
    g = report["grid"]
    fine = report["registration"]["fine"]
    return [
        f"compared area {g['compared_area_m2']:.1f} m2 on {g['cell_m']} m cells "
        f"({g['rows']} x {g['cols']})",
        f"registration: {fine['method']} fitness {fine['fitness']:.3f}, RMSE {fine['rmse']:.3f} m",
        f"volume (change areas, {report['correction']['method']} correction): "
        f"net {v['net']:+.2f} m3  cut {v['cut']:.2f} m3  fill {v['fill']:.2f} m3",
        f"volume (uncompensated): net {u['net']:+.2f} m3  cut {u['cut']:.2f} m3  fill {u['fill']:.2f} m3",
        f"uncertainty (95 %): net ±{report['uncertainty_m3']['net']:.2f} m3, "
        f"level of detection {report['uncertainty_m3']['lod_m']:.3f} m",
        f"total time {sum(report['timings_s'].values()):.2f} s",
        *quality_lines(report),
    ]


def quality_lines(report: dict) -> list[str]:
    """The quality verdict and its reasons, one line each."""
    q = report.get("quality")
    if not q:
        return []
    return [f"quality: {q['verdict'].upper()}"] + [f"  - {m}" for m in q["messages"]]
