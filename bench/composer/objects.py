"""What is not soil on a composed site: machines, vehicles, containers, cabins, buildings and
slabs, fences, pipe stacks, people, vegetation from grass to trees, and water in pits.

An object is ``{"kind", "role", "before": stamp | None, "after": stamp | None}`` with a stamp
``{"shape", "x", "y", "angle", "a", "b", "h"}`` (half length/width and height, m; x/y from the
after footprint's south-west corner) for each epoch it stands in. None of it is in the truth.
"""

from __future__ import annotations

import math

import numpy as np

# kind: (probability, shape, half length, half width, height (ranges), roles and their probabilities)
KINDS = {
    "building": (0.1, "box", (4.0, 15.0), (3.0, 10.0), (3.0, 10.0), {"arrived": 0.6, "both": 0.3, "left": 0.1}),
    "slab": (0.08, "slab", (2.0, 12.0), (2.0, 10.0), (0.15, 0.4), {"arrived": 0.8, "both": 0.2}),
    "machine": (
        0.13,
        "box",
        (2.5, 4.5),
        (1.2, 1.8),
        (2.5, 3.5),
        {"arrived": 0.3, "left": 0.2, "moved": 0.3, "both": 0.2},
    ),
    "vehicle": (
        0.11,
        "box",
        (2.0, 2.8),
        (0.85, 1.1),
        (1.4, 2.0),
        {"arrived": 0.3, "left": 0.2, "moved": 0.3, "both": 0.2},
    ),
    "container": (0.07, "box", (3.0, 6.1), (1.2, 1.25), (2.5, 2.9), {"arrived": 0.5, "left": 0.2, "both": 0.3}),
    "cabin": (0.06, "box", (2.2, 3.0), (1.2, 1.5), (2.6, 3.0), {"arrived": 0.5, "left": 0.2, "both": 0.3}),
    "fence": (0.06, "fence", (8.0, 30.0), (0.08, 0.12), (1.8, 2.4), {"arrived": 0.6, "both": 0.4}),
    "pipe stack": (0.06, "mound", (2.0, 4.0), (1.0, 2.0), (0.8, 1.5), {"arrived": 0.5, "left": 0.2, "both": 0.3}),
    "people": (0.05, "person", (0.25, 0.35), (0.2, 0.3), (1.6, 1.9), {"arrived": 0.7, "left": 0.3}),
    "grass": (0.1, "grass", (3.0, 15.0), (2.0, 10.0), (0.2, 0.6), {"grown": 0.6, "mown": 0.4}),
    "bush": (0.08, "bush", (0.8, 3.0), (0.8, 3.0), (0.5, 3.0), {"grown": 0.8, "cleared": 0.2}),
    "tree": (0.1, "tree", (2.0, 6.0), (2.0, 6.0), (5.0, 15.0), {"grown": 0.7, "felled": 0.3}),
}
#: LAS class a classified LiDAR survey gives each shape's hits (vegetation by height: 3/4/5)
LIDAR_CLASS = {"box": 1, "slab": 2, "fence": 1, "mound": 1, "person": 1}
#: share of a shape's footprint hit (photogrammetry, LiDAR); the rest sees the ground below
HIT = {"fence": (0.3, 0.35), "person": (0.5, 0.9), "grass": (0.95, 0.6), "bush": (0.97, 0.7), "tree": (0.99, 0.65)}
VEGETATION = ("grass", "bush", "tree")


def _u(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(*lo_hi))


def _stamps(rng: np.random.Generator, kind: str, role: str, shape: str, a: float, b: float, h: float) -> tuple:
    """(before stamp, after stamp) of an object by its role."""
    s = {"shape": shape, "x": 0.0, "y": 0.0, "angle": float(rng.uniform(0, 180)), "a": a, "b": b, "h": h}
    if role == "grown":
        lo = 0.05 if kind == "grass" else h * float(rng.uniform(0.6, 0.9))
        return dict(s, h=lo), s
    if role == "mown":
        return s, dict(s, h=0.05)
    if role in ("cleared", "felled", "left"):
        return s, None
    if role == "arrived":
        return None, s
    if role == "moved":
        return s, dict(s, angle=float(rng.uniform(0, 180)))
    return s, dict(s)


def _free(rng, r: float, aw: float, ah: float, taken: list) -> tuple[float, float] | None:
    for _ in range(60):
        x, y = float(rng.uniform(r + 0.5, aw - r - 0.5)), float(rng.uniform(r + 0.5, ah - r - 0.5))
        if all(math.hypot(x - px, y - py) > r + pr + 1.0 for px, py, pr in taken):
            return x, y
    return None


def _place(rng, obj: dict, aw: float, ah: float, taken: list) -> bool:
    for epoch in ("before", "after"):
        s = obj[epoch]
        if s is None:
            continue
        r = math.hypot(s["a"], s["b"])
        if 2 * r + 1 > min(aw, ah):
            return False
        other = obj["before"] if epoch == "after" and obj["role"] != "moved" else None
        spot = (other["x"], other["y"]) if other is not None else _free(rng, r, aw, ah, taken)
        if spot is None:
            return False
        s["x"], s["y"] = spot
        if other is None:
            taken.append((*spot, r))
    return True


def _draw_object(rng: np.random.Generator, kind: str) -> dict:
    _, shape, ra, rb, rh, roles = KINDS[kind]
    role = list(roles)[int(rng.choice(len(roles), p=list(roles.values())))]
    a, b, h = _u(rng, ra), _u(rng, rb), _u(rng, rh)
    if shape in ("bush", "tree"):
        b = a
    before, after = _stamps(rng, kind, role, shape, a, b, h)
    obj = {"kind": kind, "role": role, "before": before, "after": after}
    if kind == "slab":
        obj["lidar_class"] = int(rng.choice([1, 2]))  # classifiers often call a slab ground
    return obj


def draw_objects(rng: np.random.Generator, aw: float, ah: float, works: list[dict]) -> list[dict]:
    """0-9 objects of random kinds (not on the works), and water in some pits."""
    taken = [(f["x"], f["y"], f["radius"]) for w in works for f in w["change"]]
    kinds = list(KINDS)
    p = np.array([KINDS[k][0] for k in kinds])
    out = []
    for _ in range(int(rng.integers(0, 10))):
        obj = _draw_object(rng, kinds[int(rng.choice(len(kinds), p=p / p.sum()))])
        if _place(rng, obj, aw, ah, taken):
            out.append(obj)
    for i, w in enumerate(works):
        f = w["change"][0]
        if w["kind"] == "pit" and f["height"] > 0.5 and rng.random() < 0.25:
            out.append(
                {"kind": "water", "role": "after", "work": i, "depth_m": float(rng.uniform(0.2, 0.8)) * f["height"]}
            )
    return out


def _local(s: dict, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = math.radians(s["angle"])
    u0, v0 = x - s["x"], y - s["y"]
    return u0 * math.cos(t) + v0 * math.sin(t), -u0 * math.sin(t) + v0 * math.cos(t)


def stamp_surface(s: dict, x: np.ndarray, y: np.ndarray, g: np.ndarray, base: float, rng) -> tuple:
    """(mask of the points on the stamp's footprint, their height if hit) for points x, y with
    ground g; ``base`` the ground at the stamp's centre (roofs are flat)."""
    u, v = _local(s, x, y)
    a, b, h = s["a"], s["b"], s["h"]
    shape = s["shape"]
    if shape in ("box", "slab", "fence"):
        on = (np.abs(u) < a) & (np.abs(v) < b)
        top = np.maximum(base + h, g + 0.1) if shape == "box" else g + h
        return on, top
    rho2 = (u / a) ** 2 + (v / b) ** 2
    on = rho2 < 1.0
    dome = np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
    if shape == "mound":
        return on, g + h * dome
    if shape == "person":
        return on, g + h
    if shape == "grass":
        return on, g + h * rng.uniform(0.7, 1.3, x.shape)
    if shape == "bush":
        return on, g + h * dome * rng.uniform(0.75, 1.0, x.shape)
    return on, g + h * (0.55 + 0.45 * dome) * rng.uniform(0.92, 1.0, x.shape)  # tree crown
