"""Real-terrain pairs with an exactly known change, for the accuracy harness (issue 10).

The ground points (class 2) of the 2015 Tommy Thompson Park LiDAR survey
(``/work/shared/data/real/tommy_thompson_park_2015.laz``, or ``$SOILVOLUME_REAL_DATA``) are split
into two disjoint random halves (seeded). The first half is the "before" cloud (whole extent).
The second half, cropped to a box inside the park, gets an analytic change added to its heights
(the same feature shapes as :mod:`soilvolume.scenes.synthetic`: flat-topped cones, flat-bottomed pits,
a flat-bottomed rectangular excavation with sloped sides) and a GPS-like misalignment about the
box centre, ``p_surveyed = R (p - c) + c + shift``. Both halves sample the same real surface at
different places, so the only true change is the added dz: ``truth`` net/cut/fill are its exact
integrals (analytic, see ``soilvolume.scenes.synthetic.finish_features``) and ``truth["transform"]`` is
the inverse of the misalignment, as in ``truth.json`` of the synthetic pairs.

The cloud is sparse (~0.19 ground points per m2 in the whole file, half of it per epoch), so the
features are large (30 m piles, an excavation of ~120 m x 176 m). Not part of the engine.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from soilvolume.scenes.synthetic import feature_area, features_dz, finish_features

DEFAULT_REAL = Path("/work/shared/data/real")
SOURCE = "tommy_thompson_park_2015.laz"
CRS = "EPSG:26917"
# the after box (absolute NAD83 / UTM 17N): dense ground, away from the shore and the bays
BOX = (634150.0, 4831390.0, 634370.0, 4831610.0)
SHIFT_M = (2.0, -1.5, 0.3)
ROTATION_DEG = (0.2, -0.3, 2.0)  # roll, pitch, yaw about the after centre

CASES = {
    # a pile and a pit, ~11 % of the after box
    "pilepit": "a 6 m pile (r 30 m) and a 3 m pit (r 28 m), 11 % of the after box",
    # an excavation over 45 % of the after box and a tall pile beside it (~51 %)
    "excavation": "a 4 m deep excavation over 45 % of the after box + a 10 m pile (51 %)",
}


def real_dir() -> Path:
    """``$SOILVOLUME_REAL_DATA``, else ``../shared/data/real`` beside the repository (as the
    tests look for it), else ``/work/shared/data/real``."""
    env = os.environ.get("SOILVOLUME_REAL_DATA")
    if env:
        return Path(env)
    beside = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
    return beside if beside.exists() else DEFAULT_REAL


def available() -> bool:
    return (real_dir() / SOURCE).exists()


def features(case: str) -> list[dict]:
    """The analytic change features of ``case`` in absolute coordinates (with ``volume``)."""
    x0, y0, x1, y1 = BOX
    w, h = x1 - x0, y1 - y0
    if case == "pilepit":
        feats = [
            dict(
                kind="cone",
                sign=1.0,
                x=x0 + 60.0,
                y=y0 + 150.0,
                r_bottom=30.0,
                r_top=10.0,
                height=6.0,
                exact_outline=True,
                name="pile (truncated cone)",
            ),
            dict(
                kind="cone",
                sign=-1.0,
                x=x0 + 150.0,
                y=y0 + 70.0,
                r_bottom=28.0,
                r_top=12.0,
                height=3.0,
                exact_outline=True,
                name="pit (flat-bottomed truncated cone)",
            ),
        ]
    elif case == "excavation":
        b = 0.4 * h
        a = 0.45 * w * h / (4.0 * b)
        rp, gap = 30.0, 6.0
        width = 2.0 * a + gap + 2.0 * rp
        ex = (x0 + x1) / 2.0 - width / 2.0 + a
        feats = [
            dict(
                kind="rect",
                sign=-1.0,
                x=ex,
                y=(y0 + y1) / 2.0,
                a=a,
                b=b,
                height=4.0,
                run=8.0,
                angle_deg=0.0,
                exact_outline=True,
                name="excavation (flat-bottomed, 45 %)",
            ),
            dict(
                kind="cone",
                sign=1.0,
                x=ex + a + gap + rp,
                y=(y0 + y1) / 2.0 + 0.2 * h,
                r_bottom=rp,
                r_top=8.0,
                height=10.0,
                exact_outline=True,
                name="tall pile (truncated cone)",
            ),
        ]
    else:
        raise ValueError(f"unknown real-terrain case {case!r} ({', '.join(CASES)})")
    return finish_features(feats)


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    r, p, y = np.radians([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _write_las(path: Path, xyz: np.ndarray) -> None:
    import laspy
    import pyproj

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = np.floor(xyz.min(axis=0) / 1000.0) * 1000.0
    header.scales = np.array([0.001, 0.001, 0.001])
    header.add_crs(pyproj.CRS.from_user_input(CRS))
    header.generating_software = "soilvolume bench/real_terrain.py"
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.classification = np.full(len(xyz), 2, np.uint8)
    las.write(str(path))


def write_pair(
    case: str, seed: int, directory: Path, shift_m=SHIFT_M, rotation_deg=ROTATION_DEG
) -> tuple[Path, Path, Path]:
    """Write before.las, after.las and truth.json of a real-terrain case into ``directory``
    (misalignment of the after half: ``shift_m``, ``rotation_deg`` = roll, pitch, yaw)."""
    import laspy

    las = laspy.read(str(real_dir() / SOURCE))
    ground = np.asarray(las.classification) == 2
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])[ground]
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 10]))
    half = rng.random(len(xyz)) < 0.5
    before, after = xyz[half], xyz[~half]
    x0, y0, x1, y1 = BOX
    inside = (after[:, 0] >= x0) & (after[:, 0] <= x1) & (after[:, 1] >= y0) & (after[:, 1] <= y1)
    after = after[inside].copy()
    feats = features(case)
    after[:, 2] += features_dz(after[:, 0], after[:, 1], feats)
    # GPS-like misalignment about the box centre at ground height
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    near = np.hypot(before[:, 0] - cx, before[:, 1] - cy) < 15.0
    c = np.array([cx, cy, float(np.median(before[near, 2]))])
    R = _rotation(*rotation_deg)
    t = np.asarray(shift_m, dtype=np.float64)
    surveyed = (after - c) @ R.T + c + t
    T = np.eye(4)  # surveyed -> true
    T[:3, :3] = R.T
    T[:3, 3] = c - R.T @ (c + t)
    fill = sum(f["volume"] for f in feats if f["sign"] > 0)
    cut = sum(f["volume"] for f in feats if f["sign"] < 0)
    area = (x1 - x0) * (y1 - y0)
    truth = {
        "net": float(fill - cut),
        "cut": float(cut),
        "fill": float(fill),
        "transform": T.tolist(),
        "misalignment": {
            "center": c.tolist(),
            "rotation_matrix": R.tolist(),
            "shift_m": list(shift_m),
            "rotation_deg": list(rotation_deg),
            "convention": "p_surveyed = R (p_true - center) + center + shift; "
            "transform is its inverse (surveyed -> true)",
        },
        "after_footprint": list(BOX),
        "features": feats,
        "change_fraction": sum(feature_area(f) for f in feats) / area,
        "crs": CRS,
        "seed": int(seed),
        "case": case,
        "source": SOURCE,
        "points": {"before": int(len(before)), "after": int(len(surveyed))},
        "cell_note": "net/cut/fill are exact integrals of the added analytic dz",
    }
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    pb, pa, pt = d / "before.las", d / "after.las", d / "truth.json"
    _write_las(pb, before)
    _write_las(pa, surveyed)
    pt.write_text(json.dumps(truth, indent=2) + "\n")
    return pb, pa, pt


def after_density(seed: int = 0) -> float:
    """Points per m2 of the after half in the box (a quick check of the setup)."""
    import laspy

    las = laspy.read(str(real_dir() / SOURCE))
    g = np.asarray(las.classification) == 2
    x, y = np.asarray(las.x)[g], np.asarray(las.y)[g]
    x0, y0, x1, y1 = BOX
    n = int(((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).sum())
    return 0.5 * n / ((x1 - x0) * (y1 - y0))


if __name__ == "__main__":
    print(f"after density ~{after_density():.3f} pts/m2; cases: {', '.join(CASES)}")
    for name in CASES:
        fs = features(name)
        print(
            name,
            [(f["name"], round(f["volume"], 1)) for f in fs],
            f"{sum(feature_area(f) for f in fs) / ((BOX[2] - BOX[0]) * (BOX[3] - BOX[1])):.1%}",
            math.isfinite(sum(f["volume"] for f in fs)),
        )
