"""The ground of a synthetic world before any change: tilt, long waves, hills, roughness,
ditches, a berm and mounds, drawn from a seeded stream and evaluated at any x/y."""

from __future__ import annotations

import math

import numpy as np

from .config import SceneConfig


class Terrain:
    """The before epoch's ground height (m) at local x/y, drawn from ``rng`` over ``cfg``'s area."""

    def __init__(self, rng: np.random.Generator, cfg: SceneConfig, box: tuple[float, float, float, float]) -> None:
        bw, bh = cfg.before_size
        self.slope_deg = cfg.slope_deg
        self.z0 = rng.uniform(58.0, 66.0)
        self.tilt = rng.uniform(-0.02, 0.02, 2)
        self.centre = (bw / 2.0, bh / 2.0)
        self.waves = _waves(rng)
        self.waves[:3, 0] *= cfg.relief
        self.hills = np.column_stack(
            [rng.uniform(-2.5, 3.0, 4), rng.uniform(0, bw, 4), rng.uniform(0, bh, 4), rng.uniform(10.0, 30.0, 4)]
        )
        self.hills[:, 0] *= cfg.relief
        self.lines = _lines(rng, box)
        ax0, ay0, ax1, ay1 = box
        nm = 30
        self.mounds = np.column_stack(
            [
                rng.uniform(0.15, 0.5, nm) * rng.choice([-1, 1], nm),
                rng.uniform(ax0 - 10, ax1 + 10, nm),
                rng.uniform(ay0 - 10, ay1 + 10, nm),
                rng.uniform(1.0, 3.0, nm),
            ]
        )

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height (m) of the before epoch at local x/y."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        z = self.z0 + self.tilt[0] * (x - self.centre[0]) + self.tilt[1] * (y - self.centre[1])
        if self.slope_deg:
            z += math.tan(math.radians(self.slope_deg)) * (x - self.centre[0])
        for amp, kx, ky, ph in self.waves:
            z += amp * np.cos(kx * x + ky * y + ph)
        for amp, hx, hy, sig in self.hills:
            z += amp * np.exp(-((x - hx) ** 2 + (y - hy) ** 2) / (2 * sig * sig))
        for kind, x0, y0, x1, y1, height, width in self.lines:
            reach = 3.5 * width if kind == 0 else 2.0 * width + 0.5
            (xl, xh), (yl, yh) = ((min(a, b) - reach, max(a, b) + reach) for a, b in ((x0, x1), (y0, y1)))
            m = (x > xl) & (x < xh) & (y > yl) & (y < yh)
            if not m.any():
                continue
            px, py = x[m], y[m]
            dx, dy = x1 - x0, y1 - y0
            t = np.clip(((px - x0) * dx + (py - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
            d = np.hypot(px - x0 - t * dx, py - y0 - t * dy)
            if kind == 0:  # ditch: gaussian cross-section
                prof = np.exp(-d * d / (2 * width * width))
            else:  # berm/embankment: flat crest of half-width `width`, 1:1-ish side slopes
                prof = np.clip((width + 0.5 + abs(height) - d) / (abs(height) + 0.5), 0.0, 1.0)
            z[m] += height * prof
        for amp, mx, my, sig in self.mounds:
            m = (np.abs(x - mx) < 3 * sig) & (np.abs(y - my) < 3 * sig)
            if m.any():
                z[m] += amp * np.exp(-((x[m] - mx) ** 2 + (y[m] - my) ** 2) / (2 * sig * sig))
        return z


def _waves(rng: np.random.Generator) -> np.ndarray:
    """(amplitude, kx, ky, phase) of 3 long waves and 14 short ones."""
    waves = []
    for amp_lo, amp_hi, wl_lo, wl_hi, n in ((0.5, 1.5, 60.0, 200.0, 3), (0.02, 0.08, 2.0, 12.0, 14)):
        for _ in range(n):
            th = rng.uniform(0, 2 * np.pi)
            k = 2 * np.pi / rng.uniform(wl_lo, wl_hi)
            waves.append((rng.uniform(amp_lo, amp_hi), k * np.cos(th), k * np.sin(th), rng.uniform(0, 2 * np.pi)))
    return np.array(waves)


def _lines(rng: np.random.Generator, box: tuple[float, float, float, float]) -> np.ndarray:
    """(kind, x0, y0, x1, y1, height, width) of two ditches (0) and a berm (1) across the after ``box``."""
    ax0, ay0, ax1, ay1 = box
    acx, acy = (ax0 + ax1) / 2.0, (ay0 + ay1) / 2.0
    aw, ah = ax1 - ax0, ay1 - ay0
    th0 = rng.uniform(0, np.pi)
    lines = []
    for kind, ang in ((0, th0), (0, th0 + rng.uniform(1.0, 2.1)), (1, th0 + rng.uniform(0.5, 1.0))):
        px, py = acx + rng.uniform(-0.3, 0.3) * aw, acy + rng.uniform(-0.3, 0.3) * ah
        half = rng.uniform(25.0, 50.0)
        dx, dy = np.cos(ang) * half, np.sin(ang) * half
        height = -rng.uniform(0.5, 1.0) if kind == 0 else rng.uniform(0.6, 1.2)
        width = rng.uniform(0.6, 1.2) if kind == 0 else rng.uniform(1.2, 2.0)
        lines.append((kind, px - dx, py - dy, px + dx, py + dy, height, width))
    return np.array(lines)
