"""A seeded site surveyed four times with exact volumes per period (a pit dug, deepened, partly
backfilled; a pile placed, partly hauled away; a windrow placed, removed), each epoch with its own
GPS error, so each registration into E0's frame is known (``truth["epochs"]``). Terrain from
:class:`world.World`; features nested from epoch to epoch, so each one's change has one sign."""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import replace
from pathlib import Path

import laspy
import numpy as np

from ..registration.rigid import rotation_zyx
from .config import CLASS_GROUND, SceneConfig
from .features import after_box, cone, features_dz, finish_features, rect
from .synthetic import las_header
from .world import World

DATES = ("2026-03-02", "2026-03-09", "2026-03-16", "2026-03-23")
#: per epoch: (shift m, roll/pitch/yaw deg) of its GPS error
GPS_ERRORS = (
    ((0.4, -0.3, 0.1), (0.05, -0.04, 0.3)),
    ((2.0, -1.5, 0.3), (0.3, -0.2, 2.0)),
    ((-1.6, 1.2, -0.2), (-0.2, 0.25, -1.5)),
    ((1.1, 1.7, 0.25), (0.15, 0.3, 1.2)),
)
CONFIG = SceneConfig(before_size=(130.0, 125.0), after_size=(67.0, 63.0), change="none")
#: a site whose files declare a vertical datum (NAVD88 height) yet carry 2-5 m and 1-3 degrees of
#: GPS error: smooth terrain, where the margin of a later survey agrees with E0's surface as
#: surveyed although it lies metres off (:func:`write_series` with ``datum=True``, three epochs)
DATUM_CONFIG = replace(CONFIG, relief=0.3, vertical_datum="EPSG:5703")
DATUM_ERRORS = (
    ((-1.2, 0.8, 0.05), (0.05, -0.05, -0.8)),
    ((2.4, -1.9, 0.1), (0.2, -0.15, 1.6)),
    ((-2.1, 2.6, -0.1), (-0.15, 0.2, -2.2)),
)
PILE_SLOPE = 0.6  # the pile's side slope (height per metre of run)


def epoch_features(cx: float, cy: float) -> list[dict[str, dict]]:
    """Each epoch's features by slot (pit, pile, windrow), around the later surveys' centre."""

    def pit(h: float) -> dict:
        return rect(-1.0, cx - 14.0, cy + 9.0, 7.0, 6.0, h, h, 0.0, f"pit {h:g} m deep")

    def pile(h: float) -> dict:
        return cone(1.0, cx + 13.0, cy - 6.0, 8.0, 8.0 - h / PILE_SLOPE, h, f"pile {h:g} m high")

    windrow = rect(1.0, cx - 8.0, cy - 16.0, 10.0, 2.5, 1.8, 1.8, 0.0, "windrow")
    epochs = [{}, {"pit": pit(2.0), "pile": pile(3.6)}]
    epochs += [{"pit": pit(3.5), "pile": pile(1.5), "windrow": windrow}, {"pit": pit(1.0), "pile": pile(1.5)}]
    for feats in epochs:
        finish_features(list(feats.values()))
    return epochs


def change_truth(a: dict[str, dict], b: dict[str, dict]) -> dict[str, float]:
    """net/cut/fill (m3) from features ``a`` to ``b``: each slot's change has one sign."""
    va, vb = ({k: f["sign"] * f["volume"] for k, f in feats.items()} for feats in (a, b))  # signed volumes
    moves = [vb.get(k, 0.0) - va.get(k, 0.0) for k in set(va) | set(vb)]
    fill, cut = sum(m for m in moves if m > 0), -sum(m for m in moves if m < 0)
    return {"net": fill - cut, "cut": cut, "fill": fill}


def misalignment(k: int, centre_abs: np.ndarray, errors=GPS_ERRORS) -> np.ndarray:
    """Epoch ``k``'s GPS error (``errors[k]``) as a 4x4 on absolute coordinates: true -> surveyed,
    ``p_s = R (p - c) + c + t``."""
    shift, deg = errors[k]
    m = np.eye(4)
    m[:3, :3] = rotation_zyx(*np.radians(deg))
    m[:3, 3] = centre_abs + np.asarray(shift) - m[:3, :3] @ centre_abs
    return m


def _write_epoch(path: Path, xyz: np.ndarray, config: SceneConfig, date: str) -> Path:
    """One survey as LAS: ground points (class 2), the CRS, the survey date in the header."""
    header = las_header(config, 0.001)
    header.creation_date = dt.date.fromisoformat(date)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.classification = np.full(len(xyz), CLASS_GROUND, np.uint8)
    las.write(str(path))
    return path


def write_series(
    directory, seed: int = 0, density: tuple[float, float] = (6.0, 10.0), datum: bool = False
) -> tuple[list[Path], dict]:
    """Write ``epoch0.las`` .. ``epoch3.las`` (class 2, CRS, survey date) and ``truth.json``: (paths,
    truth). ``density``: points per m2 of E0 and of the later surveys; ``datum``: the three-epoch
    site of :data:`DATUM_CONFIG` and :data:`DATUM_ERRORS` instead."""
    config, errors = (DATUM_CONFIG, DATUM_ERRORS) if datum else (CONFIG, GPS_ERRORS)
    world = World(seed, config)
    ax0, ay0, ax1, ay1 = after_box(config)
    cx, cy = (ax0 + ax1) / 2.0, (ay0 + ay1) / 2.0
    origin = np.asarray(config.origin, dtype=np.float64)
    centre = np.array([cx, cy, float(world.terrain(np.array([cx]), np.array([cy]))[0])]) + origin
    feats = epoch_features(cx, cy)[: len(errors)]
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths, epochs = [], []
    m0 = misalignment(0, centre, errors)
    for k, fk in enumerate(feats):
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 21, k]))
        box = (0.0, 0.0, *config.before_size) if k == 0 else (ax0, ay0, ax1, ay1)
        n = int(density[0 if k == 0 else 1] * (box[2] - box[0]) * (box[3] - box[1]))
        x, y = rng.uniform(box[0], box[2], n), rng.uniform(box[1], box[3], n)
        z = world.terrain(x, y) + features_dz(x, y, list(fk.values())) + rng.normal(0.0, config.noise_m, n)
        xyz = np.column_stack([x, y, z]) + origin
        mk = misalignment(k, centre, errors)
        xyz = xyz @ mk[:3, :3].T + mk[:3, 3]
        paths.append(_write_epoch(d / f"epoch{k}.las", xyz, config, DATES[k]))
        to_e0 = m0 @ np.linalg.inv(mk)  # surveyed k -> true -> surveyed 0
        seen = mk[:3, :3] @ centre + mk[:3, 3]  # the works' centre as epoch k surveyed it
        epochs.append(
            {
                "path": str(paths[-1]),
                "date": DATES[k],
                "points": n,
                "transform": to_e0.tolist(),
                "centre": seen.tolist(),
            }
        )
    truth = {
        "seed": int(seed),
        "epochs": epochs,
        "periods": [{"from": i, "to": i + 1, **change_truth(feats[i], feats[i + 1])} for i in range(len(feats) - 1)],
        "cumulative": {"from": 0, "to": len(feats) - 1, **change_truth(feats[0], feats[-1])},
        "convention": "transform: epoch k's surveyed absolute coordinates -> E0's (4x4); centre: the works' "
        "centre as epoch k surveyed it; volumes exact (m3)",
    }
    (d / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return paths, truth
