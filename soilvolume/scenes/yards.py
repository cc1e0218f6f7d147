"""Seeded stockpile yards with exact truth, for the stockpile inventory's tests.

A yard is two fields of slots side by side: the western field is level, the eastern one rises
eastwards at ``slope`` (the ground is continuous: the kink runs between the fields, under no
pile). Each slot holds one pile drawn by the seed: a cone, a truncated cone, an irregular pile
(a star-shaped toe, optionally flat-topped) or a windrow (a hip-roofed prism, optionally with a
flat crest, turned at any angle). Points are spread uniformly with Gaussian height noise.

Truth per pile (exact integrals; the ground under each toe polygon is a plane ``g``): the pile's
own volume above the ground, which the triangulated and plane bases give; over a level base ``Z``
the net volume inside the polygon is that volume plus ``area * (g(area centroid) - Z)``, with
``Z`` the lowest or highest toe height (a polygon vertex: ``g`` is linear), their mean along the
toe (``g`` at the ring's length centroid) or a given elevation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import Polygon

SLOT = 32.0  # m: the side of a pile's square slot
MARGIN = 1.5  # m: how far outside its toe a pile's polygon is drawn (as a surveyor draws it, on the ground)
SHAPES = ("cone", "frustum", "irregular", "windrow")


@dataclass(frozen=True)
class PileTruth:
    """One seeded pile: ``shape``, its true toe ``outline``, the ``polygon`` drawn around it,
    ``volume_m3`` above its ground, ``ground`` (a, b, c of ``z = a + b x + c y`` under the polygon),
    ``density`` (t/m3), ``max_height_m`` and ``on_slope``."""

    name: str
    shape: str
    outline: Polygon
    polygon: Polygon
    volume_m3: float
    ground: tuple[float, float, float]
    density: float
    max_height_m: float
    on_slope: bool

    def ground_at(self, x: float, y: float) -> float:
        a, b, c = self.ground
        return a + b * x + c * y

    def truth(self, base: str) -> float:
        """The exact net volume (m3) inside the polygon over ``base``: a toe base name or
        ``elevation:Z``."""
        if base in ("triangulated", "plane"):
            return self.volume_m3
        verts = np.asarray(self.polygon.exterior.coords)[:-1]
        toe = [self.ground_at(x, y) for x, y in verts]
        ring = self.polygon.exterior.centroid
        levels = {"lowest": min(toe), "highest": max(toe), "average": self.ground_at(ring.x, ring.y)}
        z = float(base.partition(":")[2]) if base.startswith("elevation:") else levels[base]
        c = self.polygon.centroid
        return self.volume_m3 + self.polygon.area * (self.ground_at(c.x, c.y) - z)


@dataclass(frozen=True)
class Yard:
    """A seeded yard: its points (local m), its piles' truth, the point noise (m) and the ground
    level ``z0`` (m) of the level field."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    piles: tuple[PileTruth, ...]
    noise_m: float
    z0: float
    east: float  # m: where the eastern field starts
    slope: float  # its rise eastwards (m/m)

    def ground(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The yard's bare ground at ``x``, ``y``."""
        return _ground(x, self.z0, self.east, self.slope)


def stockpile_yard(
    seed: int = 0,
    columns: int = 3,
    rows: int = 2,
    slope: float = 0.06,
    noise: float = 0.02,
    density: float = 60.0,
    shapes: tuple[str, ...] = SHAPES,
) -> Yard:
    """A :class:`Yard` of ``columns`` x ``rows`` slots per field (level west, rising east at
    ``slope``), points at ``density`` per m2 with ``noise`` (m) of height noise; deterministic for
    a ``seed``."""
    rng = np.random.default_rng(seed)
    z0, east = 100.0, columns * SLOT
    piles, surfaces = [], []
    for field_ in range(2):
        for i in range(columns):
            for j in range(rows):
                cx, cy = (field_ * columns + i + 0.5) * SLOT, (j + 0.5) * SLOT
                shape = shapes[int(rng.integers(len(shapes)))]
                height, outline, volume = _pile(shape, cx, cy, rng)
                surfaces.append(height)
                piles.append(_truth(len(piles), shape, outline, volume, height, (z0, east, field_ * slope), rng))
    width, depth = 2 * east, rows * SLOT
    n = int(density * width * depth)
    x, y = rng.uniform(0, width, n), rng.uniform(0, depth, n)
    z = _ground(x, z0, east, slope) + sum(f(x, y) for f in surfaces) + rng.normal(0, noise, n)
    return Yard(x, y, z, tuple(piles), noise, z0, east, slope)


def _ground(x: np.ndarray, z0: float, east: float, slope: float) -> np.ndarray:
    """The level western field and the eastern field rising at ``slope`` from ``east`` on."""
    return z0 + slope * np.clip(np.asarray(x) - east, 0, None)


def _truth(k: int, shape: str, outline: Polygon, volume: float, height, yard: tuple, rng) -> PileTruth:
    """A :class:`PileTruth`: the polygon drawn :data:`MARGIN` outside the toe (a simplified
    buffer), the ground plane under it and a seeded density."""
    z0, east, slope = yard
    polygon = outline.buffer(MARGIN, quad_segs=4).simplify(0.05)
    ground = (z0 - slope * east, slope, 0.0) if slope else (z0, 0.0, 0.0)
    c = outline.centroid
    top = float(height(np.array([c.x]), np.array([c.y]))[0])
    return PileTruth(
        f"pile {k + 1}", shape, outline, polygon, volume, ground, float(rng.uniform(1.3, 2.1)), top, bool(slope)
    )


def _pile(shape: str, cx: float, cy: float, rng) -> tuple:
    """(height function of x, y, true toe outline, exact volume) of a seeded pile of ``shape``."""
    slope = rng.uniform(0.55, 0.75)  # rise over run of its sides (angle of repose about 29-37 degrees)
    if shape == "windrow":
        return windrow(cx, cy, rng.uniform(18, 26), rng.uniform(6, 10), slope, rng.uniform(0, np.pi), rng)
    radius = rng.uniform(6.0, 10.0)
    waves = rng.uniform(0.04, 0.1, 3) * rng.choice([-1, 1], 3) if shape == "irregular" else np.zeros(3)
    full = slope * radius
    cap = {"cone": 1.0, "frustum": rng.uniform(0.45, 0.7), "irregular": rng.choice([1.0, 0.75])}[shape]
    return radial(cx, cy, radius, waves, rng.uniform(0, 2 * np.pi, 3), full, cap * full)


def radial(cx: float, cy: float, r0: float, waves: np.ndarray, phases: np.ndarray, h: float, cap: float) -> tuple:
    """A pile over a star-shaped toe ``r(t) = r0 (1 + sum a_k cos(k t + p_k))`` (k = 2, 3, 4),
    its height ``min(cap, h (1 - rho / r(t)))``: a cone (round toe, no cap), a truncated cone or an
    irregular pile. The cross-section at height z is the toe shrunk by ``1 - z/h``, so its volume is
    ``A0 h / 3 (1 - (1 - cap/h)^3)`` with ``A0 = pi r0^2 (1 + sum a_k^2 / 2)``."""
    ks = np.arange(2, 2 + len(waves))

    def r_of(t: np.ndarray) -> np.ndarray:
        return r0 * (1 + np.sum(waves[:, None] * np.cos(ks[:, None] * t[None, :] + phases[:, None]), axis=0))

    def height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dx, dy = np.ravel(x) - cx, np.ravel(y) - cy
        rho, t = np.hypot(dx, dy), np.arctan2(dy, dx)
        return np.clip(np.minimum(cap, h * (1 - rho / r_of(t))), 0, None).reshape(np.shape(x))

    t = np.linspace(0, 2 * np.pi, 512, endpoint=False)
    r = r_of(t)
    outline = Polygon(np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)]))
    a0 = np.pi * r0**2 * (1 + np.sum(waves**2) / 2)
    return height, outline, a0 * h / 3 * (1 - (1 - cap / h) ** 3)


def windrow(cx: float, cy: float, length: float, width: float, slope: float, angle: float, rng) -> tuple:
    """A hip-roofed windrow of toe ``length`` x ``width`` (m) turned by ``angle``, sides rising at
    ``slope``, a ridge or (half the time) a flat crest; its cross-section at height z is
    ``(L - 2z/s)(W - 2z/s)``, so its volume is ``L W H - (L + W) H^2 / s + 4 H^3 / (3 s^2)``."""
    top = slope * width / 2
    h = top if rng.random() < 0.5 else top * rng.uniform(0.6, 0.85)
    cos, sin = np.cos(angle), np.sin(angle)

    def height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dx, dy = np.asarray(x) - cx, np.asarray(y) - cy
        u, v = dx * cos + dy * sin, -dx * sin + dy * cos
        inward = np.minimum(length / 2 - np.abs(u), width / 2 - np.abs(v))
        return np.clip(slope * inward, 0, h)

    box = shapely.box(-length / 2, -width / 2, length / 2, width / 2)
    outline = affinity.translate(affinity.rotate(box, angle, use_radians=True, origin=(0, 0)), cx, cy)
    volume = length * width * h - (length + width) * h**2 / slope + 4 * h**3 / (3 * slope**2)
    return height, outline, volume
