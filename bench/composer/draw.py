"""Draw a site's description at random from distributions of what the field brings (issue 53).

A description is a plain dict (JSON-ready): ``terrain``, ``works`` (analytic soil change),
``objects`` (what is not soil, per epoch), ``sensors`` (one per epoch), ``georef`` and
``coverage``. Everything is drawn from ``numpy.random.default_rng(SeedSequence([seed, 53]))``,
so a seed always gives the same site; the hand-made scene list plays no part in it.
"""

from __future__ import annotations

import math

import numpy as np

from .objects import draw_objects
from .works import draw_works

TERRAINS = ("flat yard", "rolling", "steep", "terraced")
SENSORS = ("photogrammetry", "airborne lidar", "drone lidar")
GEOREFS = ("precise", "gps", "datum-declared", "flight strips")
# (sensor before, sensor after): the two mixed between epochs among them
PAIRS = (
    ("photogrammetry", "photogrammetry"),
    ("airborne lidar", "photogrammetry"),
    ("drone lidar", "drone lidar"),
    ("airborne lidar", "airborne lidar"),
    ("photogrammetry", "drone lidar"),
    ("drone lidar", "photogrammetry"),
)
PAIR_P = (0.3, 0.25, 0.15, 0.1, 0.1, 0.1)
DENSITY = {  # points per m2 (log-uniform)
    "photogrammetry": (50.0, 1000.0),
    "airborne lidar": (5.0, 40.0),
    "drone lidar": (40.0, 600.0),
}
MAX_POINTS = 300_000  # per epoch: one estimate takes a few seconds on a shared 2-core machine


def _pick(rng: np.random.Generator, options, p=None):
    return options[int(rng.choice(len(options), p=p))]


def draw_terrain(rng: np.random.Generator) -> dict:
    """The site's ground: a flat yard, rolling land, a steep slope or terraces."""
    kind = _pick(rng, TERRAINS, (0.35, 0.3, 0.15, 0.2))
    t = {"kind": kind, "relief": 0.0, "slope_deg": 0.0, "terraces": []}
    if kind == "flat yard":
        t["relief"] = float(rng.uniform(0.0, 0.15))
    elif kind == "rolling":
        t["relief"] = float(rng.uniform(0.4, 1.8))
    elif kind == "steep":
        t["relief"] = float(rng.uniform(0.2, 1.0))
        t["slope_deg"] = float(rng.uniform(12.0, 30.0))
    else:  # terraces: steps across the site, each a smooth riser of 0.5-3 m
        t["relief"] = float(rng.uniform(0.0, 0.4))
        spacing, angle = float(rng.uniform(12.0, 30.0)), float(rng.uniform(0.0, 180.0))
        t["terraces"] = [spacing, angle, float(rng.uniform(0.5, 3.0)), float(rng.uniform(0.5, 3.0))]
    return t


def draw_sensors(rng: np.random.Generator, area_after: float, area_before: float) -> list[dict]:
    """One sensor per epoch with its density (as drawn, and as written after the per-site cap),
    noise, doming (photogrammetry) and the signals its files carry."""
    pair = _pick(rng, PAIRS, PAIR_P)
    out = []
    for epoch, kind in zip(("before", "after"), pair, strict=True):
        lo, hi = DENSITY[kind]
        drawn = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        area = area_before if epoch == "before" else area_after
        s = {"epoch": epoch, "kind": kind, "density_drawn": drawn, "density": min(drawn, MAX_POINTS / area)}
        if kind == "photogrammetry":
            s.update(noise_m=float(rng.uniform(0.015, 0.06)), doming_m=float(rng.uniform(-0.12, 0.12)))
            s.update(signals="rgb", shadows=float(rng.uniform(0.05, 0.25)), classes=False)
        else:
            s.update(noise_m=float(rng.uniform(0.02, 0.07)), doming_m=0.0, signals="lidar", shadows=0.0)
            s["classes"] = bool(rng.random() < (0.85 if kind == "airborne lidar" else 0.6))
        s["outliers"] = float(rng.choice([0.0, 0.001, 0.005]))
        out.append(s)
    return out


def draw_georef(rng: np.random.Generator, sensors: list[dict]) -> dict:
    """Precise, GPS (metres and degrees), files declaring a vertical datum over GPS error, or
    flight-strip steps in one epoch."""
    lidar_only = all(s["kind"] != "photogrammetry" for s in sensors)
    kind = _pick(rng, GEOREFS, (0.45, 0.2, 0.15, 0.2) if lidar_only else (0.2, 0.45, 0.2, 0.15))
    g = {"kind": kind, "shift_m": [0.0, 0.0, 0.0], "rotation_deg": [0.0, 0.0, 0.0], "strips": None}
    if kind in ("gps", "datum-declared"):
        g["shift_m"] = [float(v) for v in rng.uniform(-4.0, 4.0, 2)] + [float(rng.uniform(-1.0, 1.0))]
        g["rotation_deg"] = [float(v) for v in rng.uniform(-0.5, 0.5, 2)] + [float(rng.uniform(-3.0, 3.0))]
    if kind == "flight strips":  # alternate strips of one epoch stepped in x, y, z
        g["strips"] = {
            "epoch": _pick(rng, ("before", "after")),
            "width_m": float(rng.uniform(15.0, 40.0)),
            "angle_deg": float(rng.uniform(0.0, 180.0)),
            "step_m": [float(v) for v in rng.uniform(-0.15, 0.15, 2)] + [float(rng.uniform(-0.12, 0.12))],
        }
    g["vertical_datum"] = "EPSG:5703" if kind == "datum-declared" else None
    return g


def draw_coverage(rng: np.random.Generator) -> dict:
    """Occlusion holes per epoch and the share of the after survey's width the before one reaches."""
    overlap = 1.0 if rng.random() < 0.8 else float(rng.uniform(0.6, 0.95))
    return {"overlap": overlap, "holes": [int(rng.integers(0, 8)), int(rng.integers(0, 8))]}


def draw_site(seed: int) -> dict:
    """The description of site ``seed`` (see the module docstring)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 53]))
    aw, ah = float(rng.uniform(35.0, 90.0)), float(rng.uniform(35.0, 90.0))
    margin = float(rng.uniform(8.0, 30.0))
    size = {"after": [aw, ah], "before": [aw + 2 * margin, ah + 2 * margin]}
    terrain = draw_terrain(rng)
    works = draw_works(rng, aw, ah)

    objects = draw_objects(rng, aw, ah, works)
    sensors = draw_sensors(rng, aw * ah, size["before"][0] * size["before"][1])
    return {
        "seed": int(seed),
        "size": size,
        "terrain": terrain,
        "works": works,
        "objects": objects,
        "sensors": sensors,
        "georef": draw_georef(rng, sensors),
        "coverage": draw_coverage(rng),
        "z0": float(rng.uniform(20.0, 400.0)),
    }
