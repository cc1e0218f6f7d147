"""Site conditions that hide or imitate earthworks (issue 45; its arrived equipment in :mod:`.nuisances`):
occlusion holes (``holes``, some on a change's edge); standing water in the after survey's pits
(``water_m``: no point on it, the truth still the bottom); a before survey short of the after one
(``overlap``: the share of the after footprint's width it reaches from the west); a meadow mown
between the surveys (``meadow``: 0.3-0.7 m grass, then stubble; fresh soil carries none)."""

from __future__ import annotations

import math

import numpy as np

from .config import SceneConfig
from .features import change_dz, clear_of
from .nuisances import PATCH


def meadow_row(cfg: SceneConfig, box: tuple[float, float, float, float], rng: np.random.Generator) -> tuple:
    """The meadow's feature row: an ellipse over ``cfg.meadow`` of the after ``box``, mown to stubble."""
    x0, y0, x1, y1 = box
    area = cfg.meadow * (x1 - x0) * (y1 - y0)
    ratio = (x1 - x0) / (y1 - y0)
    b = math.sqrt(area / (math.pi * ratio))
    a = ratio * b
    tall = rng.uniform(0.3, 0.7)
    return (PATCH, (x0 + x1) / 2.0, (y0 + y1) / 2.0, 0.0, a, b, tall, a, b, 0.05, max(a, b))


def water_levels(world) -> list[tuple[dict, float]]:
    """(pit, its water level: ``water_m`` above its lowest point) for every pit of the world."""
    out = []
    for f in world.changes:
        if f["sign"] < 0:  # water pools at the lowest point of the pit's bottom
            u = np.linspace(-f["radius"], f["radius"], 81)
            x, y = (a.ravel() for a in np.meshgrid(f["x"] + u, f["y"] + u))
            dz = change_dz(x, y, world.cfg, world.seed)
            bottom = float(np.min((world.terrain(x, y) + dz)[dz < 0]))
            out.append((f, bottom + world.cfg.water_m))
    return out


def dry(levels, x: np.ndarray, y: np.ndarray, g: np.ndarray, dz: np.ndarray) -> np.ndarray:
    """Mask of the after survey's points (ground ``g``) not under the water ``levels``."""
    keep = np.ones(x.shape, bool)
    for f, level in levels:
        near = (dz < 0) & (np.hypot(x - f["x"], y - f["y"]) < f["radius"] + 1.0)
        keep &= ~(near & (g < level))
    return keep


def reached(world, epoch: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Mask of the points a survey returns: not in its holes nor (before) east of its reach."""
    keep = np.ones(x.shape, bool)
    if world.holes[epoch] is not None:
        keep &= ~world.lookup(world.holes[epoch], world.hole_res, x, y)
    if epoch == 0 and world.cfg.overlap < 1.0:
        keep &= x < world.ax0 + world.cfg.overlap * (world.ax1 - world.ax0)
    return keep


def occlusion_holes(world, rng: np.random.Generator, n: int) -> np.ndarray | None:
    """An epoch's ``n`` occlusion holes (blobs, every third on a change's edge) as a mask; None for none."""
    if n <= 0:
        return None
    bw, bh = world.cfg.before_size
    grid = np.zeros((int(math.ceil(bh / world.hole_res)) + 1, int(math.ceil(bw / world.hole_res)) + 1), dtype=bool)
    for k in range(n):
        r = rng.uniform(1.5, 3.0)
        if k % 3 == 0 and world.changes:  # on a change edge
            c = world.changes[int(rng.integers(len(world.changes)))]
            ang = rng.uniform(0, 2 * np.pi)
            if c.get("exact_outline") and c["kind"] == "rect":  # on the rectangle's edge
                ca, sa = np.cos(ang), np.sin(ang)
                reach = 1.0 / max(abs(ca) / c["a"], abs(sa) / c["b"])
                t = math.radians(c["angle_deg"])
                u, v = reach * ca, reach * sa
                x = c["x"] + u * math.cos(t) - v * math.sin(t)
                y = c["y"] + u * math.sin(t) + v * math.cos(t)
            else:
                rr = c["r_bottom"] if c["kind"] == "cone" else min(c["a"], c["b"])
                x, y = c["x"] + rr * np.cos(ang), c["y"] + rr * np.sin(ang)
        else:
            for _try in range(50):
                x, y = rng.uniform(world.ax0 + 2, world.ax1 - 2), rng.uniform(world.ay0 + 2, world.ay1 - 2)
                if all(clear_of(c, x, y, r + 1.0) for c in world.changes):
                    break
        # irregular blob: union of three discs
        for _ in range(3):
            cx, cy = x + rng.uniform(-0.6, 0.6) * r, y + rng.uniform(-0.6, 0.6) * r
            world.stamp(grid, world.hole_res, cx, cy, r * rng.uniform(0.5, 0.9), True)
    return grid
