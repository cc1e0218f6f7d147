"""Seeded synthetic before/after point-cloud pairs with a KNOWN soil volume change.

The geometry follows the paper (Shao et al.): a wide "before" UAV/SfM survey of about
158 m x 154 m and a smaller "after" survey of about 67 m x 62.7 m inside it, in a UTM CRS with a
realistic absolute offset (default EPSG:32654, x = 500 000 + local x, y = 3 900 000 + local y,
z about 50-80 m).

Pure numpy (no Open3D); the paper-sized pair (4 M points) generates in a few seconds, and
:func:`write_pair_streaming` writes pairs of any size chunk by chunk in bounded memory.

Frames and truth convention
---------------------------
* Local coordinates: ``x`` in ``[0, before_size[0]]``, ``y`` in ``[0, before_size[1]]``;
  absolute = local + ``config.origin``. The *true* frame is the before survey's frame.
* The after survey is sampled on its footprint in the true frame from
  ``terrain + dz + doming + bias`` (plus vegetation, objects, noise, outliers), then the GPS
  misalignment is applied: ``p_surveyed = R (p - c) + c + shift`` with ``R = Rz(yaw) Ry(pitch)
  Rx(roll)`` and ``c`` the after footprint centre on the terrain. ``truth["transform"]`` is the
  4x4 matrix (absolute coordinates, row-major list) mapping surveyed-after points onto the true
  frame, i.e. the inverse of that misalignment.
* ``truth["fill"]``/``truth["cut"]`` (both >= 0, m3) and ``truth["net"] = fill - cut`` are exact
  integrals of the analytic ground change ``dz(x, y)`` (three piles: two flat-topped cones and one
  flat-topped rectangular pile with equal side slopes, plus one flat-bottomed conical pit). They
  EXCLUDE vegetation growth, objects, doming, vertical bias, noise and outliers: a perfect method
  recovers exactly these numbers. The piles and the pit do not overlap, so cut is the pit and
  fill the piles.
* Other change kinds (``SceneConfig.change``), for pairs where the change dominates: ``"pit"``
  (one flat-bottomed conical pit over 5 % of the after footprint), ``"pile"`` (one flat-topped
  conical pile over 10 %), ``"excavation"`` (a flat-bottomed rectangular excavation with sloped
  sides whose outline covers exactly ``change_fraction`` of the after footprint, plus a tall
  conical pile beside it near one edge; 2-75 %) and ``"none"``. Their volumes are the same exact
  analytic integrals and their features never overlap (cut = the pits/excavation, fill = the
  piles). Clutter and holes are placed around their true outlines.

LAS classes
-----------
``2`` ground (including the changed ground, i.e. pile and pit surfaces); ``3``/``4``/``5`` low /
medium / high vegetation (by height above ground: < 0.5 m, < 2 m, above); ``6`` vehicles;
``1`` (unclassified) boulders AND outliers/floaters: outliers are deliberately NOT given class 7,
so a pipeline must reject them with its own filters (those that hit ground-classified areas keep
class 1, so a class-2 filter removes them; the others remain for robust statistics to handle).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

__all__ = [
    "SceneConfig",
    "Scene",
    "make_pair",
    "write_pair",
    "write_pair_streaming",
    "scene_truth",
    "iter_epoch",
    "change_dz",
    "features_dz",
    "finish_features",
    "feature_area",
    "CHANGE_KINDS",
]

CHUNK_POINTS = 1_000_000  # points per generation chunk (fixed: results never depend on the caller)

CLASS_GROUND = 2
CLASS_VEHICLE = 6
CLASS_BOULDER = 1
CLASS_OUTLIER = 1


@dataclass(frozen=True)
class SceneConfig:
    """Parameters of a synthetic pair (lengths in metres, angles in degrees)."""

    before_size: tuple[float, float] = (158.0, 154.0)
    after_size: tuple[float, float] = (67.0, 62.7)
    before_points: int = 250_000  # "paper" scale is 2_500_000
    after_points: int = 150_000  # "paper" scale is 1_500_000
    shift_m: tuple[float, float, float] = (2.0, -1.5, 0.3)  # GPS misalignment of the after cloud
    rotation_deg: tuple[float, float, float] = (0.3, -0.2, 2.0)  # roll, pitch, yaw (after centre)
    noise_m: float = 0.03  # gaussian vertical SfM noise (each epoch)
    doming_m: float = 0.0  # amplitude of a smooth dome/bowl added to the after epoch
    vertical_bias_m: float = 0.0  # planar bias (offset + small tilt) added to the after epoch
    outlier_fraction: float = 0.0  # isolated outliers incl. floaters (class 1)
    holes: int = 0  # occlusion holes (no points) per epoch, some on change edges
    vegetation: bool = False  # bushes in both epochs, grown in the after epoch (class 3/4/5)
    objects: bool = False  # vehicles (class 6) and boulders (class 1), same place in both epochs
    relief: float = 1.0  # scale of the long waves and hills (0 = a tilted plane with local detail)
    # "piles" (3 piles ~1020 m3 + one pit ~69 m3, ~15 % of the after footprint), "none", "pit" (one
    # flat-bottomed pit, 5 %), "pile" (one flat-topped pile, 10 %) or "excavation" (a flat-bottomed
    # excavation over `change_fraction` of the after footprint plus a tall pile near one edge)
    change: str = "piles"
    crs: str = "EPSG:32654"
    origin: tuple[float, float, float] = (500_000.0, 3_900_000.0, 0.0)  # added to local coords
    # change="excavation": fraction of the after footprint the excavation's outline covers
    change_fraction: float = 0.4

    @classmethod
    def paper(cls, **overrides) -> SceneConfig:
        """The paper-sized, realistic scene: 2.5 M + 1.5 M points with every nuisance on."""
        base = cls(
            before_points=2_500_000,
            after_points=1_500_000,
            shift_m=(2.5, -1.8, 0.4),
            rotation_deg=(0.3, -0.2, 2.5),
            noise_m=0.03,
            doming_m=0.03,
            outlier_fraction=0.005,
            holes=8,
            vegetation=True,
            objects=True,
        )
        return replace(base, **overrides)

    @classmethod
    def small(cls, **overrides) -> SceneConfig:
        """Same geometry as the default, ~60 k + 40 k points, for fast tests."""
        return replace(cls(before_points=60_000, after_points=40_000), **overrides)

    def with_total_points(self, total: int) -> SceneConfig:
        """A copy with ``total`` points split between the epochs in the current ratio."""
        frac = self.before_points / float(self.before_points + self.after_points)
        nb = int(round(total * frac))
        return replace(self, before_points=nb, after_points=int(total) - nb)


@dataclass
class Scene:
    """A generated pair. Coordinates are ABSOLUTE (origin added), float64, shape (N, 3)."""

    before: np.ndarray  # in the before (= true) frame
    after: np.ndarray  # as surveyed (misaligned by the GPS error)
    before_class: np.ndarray  # uint8 LAS classes, see the module docstring
    after_class: np.ndarray
    truth: dict
    config: SceneConfig
    seed: int = 0

    def change_dz(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The true ground change dz (m) at ABSOLUTE x/y of the true frame."""
        o = self.config.origin
        return change_dz(np.asarray(x) - o[0], np.asarray(y) - o[1], self.config)


# ----------------------------------------------------------------------------------------------
# geometry shared by both epochs


def _after_box(cfg: SceneConfig) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) of the after footprint, local frame (true frame)."""
    bw, bh = cfg.before_size
    aw, ah = cfg.after_size
    cx = bw / 2.0 + min(3.0, 0.04 * bw)
    cy = bh / 2.0 - min(2.0, 0.03 * bh)
    cx = min(max(cx, aw / 2.0), bw - aw / 2.0)
    cy = min(max(cy, ah / 2.0), bh - ah / 2.0)
    return cx - aw / 2.0, cy - ah / 2.0, cx + aw / 2.0, cy + ah / 2.0


CHANGE_KINDS = ("piles", "none", "pit", "pile", "excavation")


def _change_features(cfg: SceneConfig) -> list[dict]:
    """The analytic change features (positions relative to the after footprint centre, scaled
    down if the after footprint is smaller than the default)."""
    if cfg.change == "none":
        return []
    if cfg.change not in CHANGE_KINDS:
        raise ValueError(f"unknown change {cfg.change!r} ({', '.join(CHANGE_KINDS)})")
    x0, y0, x1, y1 = _after_box(cfg)
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    s = min(1.0, (x1 - x0) / 67.0, (y1 - y0) / 62.7)
    if cfg.change != "piles":
        return finish_features(_single_features(cfg, x0, y0, x1, y1, s))
    feats = [
        # flat-topped cone: sign, bottom radius, top radius, height
        dict(kind="cone", sign=1.0, x=cx - 15 * s, y=cy + 12 * s, r_bottom=8.5 * s,
             r_top=4.5 * s, height=3.5 * s, name="pile A (truncated cone)"),
        dict(kind="cone", sign=1.0, x=cx + 14 * s, y=cy + 14 * s, r_bottom=6.5 * s,
             r_top=3.0 * s, height=3.0 * s, name="pile B (truncated cone)"),
        # rectangular pile, equal side slopes: bottom half-sizes a x b, rotated by angle
        dict(kind="rect", sign=1.0, x=cx + 12 * s, y=cy - 13 * s, a=8.0 * s, b=5.5 * s,
             height=3.0 * s, run=3.0 * s, angle_deg=25.0, name="pile C (truncated rectangular)"),
        dict(kind="cone", sign=-1.0, x=cx - 14 * s, y=cy - 14 * s, r_bottom=5.0 * s,
             r_top=2.5 * s, height=1.5 * s, name="pit (truncated cone)"),
    ]
    return finish_features(feats)


def finish_features(feats: list[dict]) -> list[dict]:
    """Add the exact ``volume`` (m3, >= 0) and the bounding ``radius`` (m) to analytic change
    features: ``cone`` (x, y, r_bottom, r_top, height; a flat-topped cone or flat-bottomed conical
    pit) and ``rect`` (x, y, a, b bottom half-sizes, height, run = horizontal run of the equal side
    slopes, angle_deg; a flat-topped pile or flat-bottomed excavation). ``sign`` +1 fill, -1 cut."""
    for f in feats:
        if f["kind"] == "cone":
            h, r1, r2 = f["height"], f["r_top"], f["r_bottom"]
            f["volume"] = math.pi * h / 3.0 * (r1 * r1 + r1 * r2 + r2 * r2)
            f["radius"] = r2
        else:
            a, b, h, run = f["a"], f["b"], f["height"], f["run"]
            k = run / h  # horizontal run per metre of height
            f["volume"] = 4.0 * (a * b * h - (a + b) * k * h * h / 2.0 + k * k * h**3 / 3.0)
            f["radius"] = math.hypot(a, b)
    return feats


def feature_area(f: dict) -> float:
    """Exact area (m2) of a change feature's outline (where its dz is not zero)."""
    if f["kind"] == "cone":
        return math.pi * f["r_bottom"] ** 2
    return 4.0 * f["a"] * f["b"]


def _single_features(cfg: SceneConfig, x0: float, y0: float, x1: float, y1: float,
                     s: float) -> list[dict]:
    """Features of the "pit", "pile" and "excavation" kinds. They carry ``exact_outline``: the
    placement of clutter and holes uses their true outline, not the bounding circle."""
    aw, ah = x1 - x0, y1 - y0
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    area = aw * ah
    if cfg.change == "pit":  # 5 % of the after footprint, 2 m deep
        rb = math.sqrt(0.05 * area / math.pi)
        return [dict(kind="cone", sign=-1.0, x=cx + 4.0 * s, y=cy - 3.0 * s, r_bottom=rb,
                     r_top=0.55 * rb, height=2.0 * s, exact_outline=True,
                     name="pit (flat-bottomed truncated cone)")]
    if cfg.change == "pile":  # 10 % of the after footprint, 5 m high
        rb = math.sqrt(0.10 * area / math.pi)
        return [dict(kind="cone", sign=1.0, x=cx - 3.0 * s, y=cy + 2.0 * s, r_bottom=rb,
                     r_top=0.35 * rb, height=5.0 * s, exact_outline=True,
                     name="pile (flat-topped truncated cone)")]
    # excavation: 2b tall (most of the footprint's height), 2a wide so that 4ab = f * area; a
    # tall conical pile beside it, the pair centred in x with equal margins
    frac = float(cfg.change_fraction)
    if not 0.02 <= frac <= 0.75:
        raise ValueError(f"change_fraction {frac} outside 0.02..0.75")
    margin_y = 0.045 * ah
    b = min(ah - 2.0 * margin_y, 1.2 * ah * math.sqrt(frac)) / 2.0
    a = frac * area / (4.0 * b)
    gap = 1.5 * s
    rp = min(9.0 * s, (aw - 4.0 * s - 2.0 * a - gap) / 2.0)  # 2 m margins at both x ends
    if rp < 3.0 * s:
        raise ValueError(f"change_fraction {frac} leaves no room for the pile")
    width = 2.0 * a + gap + 2.0 * rp
    ex = cx - width / 2.0 + a
    px = ex + a + gap + rp
    py = cy + min(0.25 * ah, ah / 2.0 - rp - 2.0 * s)
    depth, run = 2.5 * s, 3.0 * s
    return [
        dict(kind="rect", sign=-1.0, x=ex, y=cy, a=a, b=b, height=depth, run=run,
             angle_deg=0.0, exact_outline=True,
             name=f"excavation (flat-bottomed, {frac:.0%} of the after footprint)"),
        # ~42 degree sides, flat top of 0.3 x its base radius
        dict(kind="cone", sign=1.0, x=px, y=py, r_bottom=rp, r_top=0.3 * rp,
             height=0.9 * 0.7 * rp, exact_outline=True, name="tall pile (truncated cone)"),
    ]


def _outline_distance(f: dict, x: float, y: float) -> float:
    """Distance (m) from (x, y) to the outline of a change feature (0 inside)."""
    u, v = x - f["x"], y - f["y"]
    if f["kind"] == "cone":
        return max(0.0, math.hypot(u, v) - f["r_bottom"])
    t = math.radians(f["angle_deg"])
    uu = abs(u * math.cos(t) + v * math.sin(t)) - f["a"]
    vv = abs(-u * math.sin(t) + v * math.cos(t)) - f["b"]
    return math.hypot(max(uu, 0.0), max(vv, 0.0))


def _clear_of(f: dict, x: float, y: float, r: float) -> bool:
    """(x, y) with radius r is clear of change feature f (bounding circle for the original
    "piles" features, whose placement must not change; true outline for the others)."""
    if f.get("exact_outline"):
        return _outline_distance(f, x, y) > r
    return math.hypot(x - f["x"], y - f["y"]) > f["radius"] + r


def features_dz(x: np.ndarray, y: np.ndarray, feats: list[dict]) -> np.ndarray:
    """The ground change dz (m, + = fill) of analytic features (see :func:`finish_features`)
    at x/y in the features' frame."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    dz = np.zeros(np.broadcast(x, y).shape)
    x, y = np.broadcast_to(x, dz.shape), np.broadcast_to(y, dz.shape)
    for f in feats:
        R = f["radius"]
        m = (np.abs(x - f["x"]) < R) & (np.abs(y - f["y"]) < R)
        if not m.any():
            continue
        u, v = x[m] - f["x"], y[m] - f["y"]
        if f["kind"] == "cone":
            r = np.hypot(u, v)
            slope = f["height"] / (f["r_bottom"] - f["r_top"])
            h = np.clip((f["r_bottom"] - r) * slope, 0.0, f["height"])
        else:
            t = math.radians(f["angle_deg"])
            uu = np.abs(u * math.cos(t) + v * math.sin(t))
            vv = np.abs(-u * math.sin(t) + v * math.cos(t))
            d = np.minimum(f["a"] - uu, f["b"] - vv)
            h = np.clip(d * (f["height"] / f["run"]), 0.0, f["height"])
        dz[m] += f["sign"] * h
    return dz


def change_dz(x: np.ndarray, y: np.ndarray, cfg: SceneConfig) -> np.ndarray:
    """The analytic ground change dz (m, + = fill) at LOCAL x/y (true frame)."""
    return features_dz(x, y, _change_features(cfg))


class _World:
    """Terrain, features, holes and misalignment of one (seed, config): everything that is not
    per-point randomness. Built from its own RNG stream so epochs/chunks are independent."""

    def __init__(self, seed: int, cfg: SceneConfig):
        self.cfg = cfg
        self.seed = int(seed)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0]))
        bw, bh = cfg.before_size
        self.ax0, self.ay0, self.ax1, self.ay1 = _after_box(cfg)
        acx, acy = (self.ax0 + self.ax1) / 2.0, (self.ay0 + self.ay1) / 2.0
        self.changes = _change_features(cfg)

        # --- terrain: tilt + long waves + hills + roughness + ditches, berm, mounds ---
        self.z0 = rng.uniform(58.0, 66.0)
        self.tilt = rng.uniform(-0.02, 0.02, 2)
        self.centre = (bw / 2.0, bh / 2.0)
        waves = []
        for amp_lo, amp_hi, wl_lo, wl_hi, n in ((0.5, 1.5, 60.0, 200.0, 3),
                                                (0.02, 0.08, 2.0, 12.0, 14)):
            for _ in range(n):
                th = rng.uniform(0, 2 * np.pi)
                k = 2 * np.pi / rng.uniform(wl_lo, wl_hi)
                waves.append((rng.uniform(amp_lo, amp_hi), k * np.cos(th), k * np.sin(th),
                              rng.uniform(0, 2 * np.pi)))
        self.waves = np.array(waves)
        self.waves[:3, 0] *= cfg.relief
        self.hills = np.column_stack([rng.uniform(-2.5, 3.0, 4), rng.uniform(0, bw, 4),
                                      rng.uniform(0, bh, 4), rng.uniform(10.0, 30.0, 4)])
        self.hills[:, 0] *= cfg.relief
        aw, ah = self.ax1 - self.ax0, self.ay1 - self.ay0
        th0 = rng.uniform(0, np.pi)
        lines = []  # (kind, x0, y0, x1, y1, height, width) ; kind 0 ditch (gaussian), 1 berm
        for i, (kind, ang) in enumerate(((0, th0), (0, th0 + rng.uniform(1.0, 2.1)),
                                         (1, th0 + rng.uniform(0.5, 1.0)))):
            px = acx + rng.uniform(-0.3, 0.3) * aw
            py = acy + rng.uniform(-0.3, 0.3) * ah
            half = rng.uniform(25.0, 50.0)
            dx, dy = np.cos(ang) * half, np.sin(ang) * half
            height = -rng.uniform(0.5, 1.0) if kind == 0 else rng.uniform(0.6, 1.2)
            width = rng.uniform(0.6, 1.2) if kind == 0 else rng.uniform(1.2, 2.0)
            lines.append((kind, px - dx, py - dy, px + dx, py + dy, height, width))
            del i
        self.lines = np.array(lines)
        nm = 30
        self.mounds = np.column_stack([rng.uniform(0.15, 0.5, nm) * rng.choice([-1, 1], nm),
                                       rng.uniform(self.ax0 - 10, self.ax1 + 10, nm),
                                       rng.uniform(self.ay0 - 10, self.ay1 + 10, nm),
                                       rng.uniform(1.0, 3.0, nm)])

        # --- non-ground features (non-overlapping, away from the change) ---
        self.feat_res = 0.25
        self.fnx = int(math.ceil(bw / self.feat_res)) + 1
        self.fny = int(math.ceil(bh / self.feat_res)) + 1
        self.label = np.zeros((self.fny, self.fnx), dtype=np.int32)  # 0 = none, k+1 = feature k
        feats: list[tuple] = []  # (type, x, y, angle, a, b, h, a2, b2, h2, rbound)
        placed: list[tuple[float, float, float]] = []

        def free(x: float, y: float, r: float) -> bool:
            if not (r < x < bw - r and r < y < bh - r):
                return False
            for c in self.changes:
                if c.get("exact_outline"):
                    if not _clear_of(c, x, y, r + 2.0):
                        return False
                elif math.hypot(x - c["x"], y - c["y"]) < c["radius"] + r + 2.0:
                    return False
            return all(math.hypot(x - px, y - py) > r + pr + 0.5 for px, py, pr in placed)

        def place(n: int, inside_after: bool, make) -> None:
            for _ in range(n):
                for _try in range(50):
                    if inside_after:
                        x = rng.uniform(self.ax0 + 1, self.ax1 - 1)
                        y = rng.uniform(self.ay0 + 1, self.ay1 - 1)
                    else:
                        x, y = rng.uniform(0, bw), rng.uniform(0, bh)
                    params = make()
                    if free(x, y, params[-1]):
                        feats.append((params[0], x, y) + params[1:])
                        placed.append((x, y, params[-1]))
                        break

        def bush():
            r = rng.uniform(0.8, 3.0)
            h = rng.uniform(0.3, 4.0)
            r2, h2 = r * 1.1, h * 1.2 + 0.1  # grown in the after epoch
            return (0, 0.0, r, r, h, r2, r2, h2, r2)

        def vehicle():
            a, b, h = rng.uniform(2.1, 2.6), rng.uniform(0.85, 1.0), rng.uniform(1.4, 1.9)
            return (1, rng.uniform(0, np.pi), a, b, h, a, b, h, math.hypot(a, b))

        def boulder():
            a, b = rng.uniform(0.6, 1.5), rng.uniform(0.6, 1.5)
            h = rng.uniform(0.5, 1.3)
            return (2, rng.uniform(0, np.pi), a, b, h, a, b, h, max(a, b))

        if cfg.vegetation:
            place(int(bw * bh / 600), False, bush)
            place(int(aw * ah / 250), True, bush)
        if cfg.objects:
            place(5, True, vehicle)
            place(3, False, vehicle)
            place(12, True, boulder)
            place(10, False, boulder)
        self.feats = np.array(feats, dtype=np.float64).reshape(-1, 11)
        if len(self.feats):
            self.feat_zc = self.terrain(self.feats[:, 1], self.feats[:, 2])
        for k, f in enumerate(self.feats):
            self._stamp(self.label, self.feat_res, f[1], f[2], f[10] + self.feat_res, k + 1)

        # --- occlusion holes, per epoch ---
        self.hole_res = 0.1
        self.holes = [self._holes(rng, cfg.holes) for _ in range(2)]

        # --- misalignment (local frame): p_s = R (p - c) + c + t ---
        roll, pitch, yaw = np.radians(cfg.rotation_deg)
        rx = np.array([[1, 0, 0], [0, np.cos(roll), -np.sin(roll)],
                       [0, np.sin(roll), np.cos(roll)]])
        ry = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0],
                       [-np.sin(pitch), 0, np.cos(pitch)]])
        rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        self.R = rz @ ry @ rx
        self.c = np.array([acx, acy, float(self.terrain(np.array([acx]), np.array([acy]))[0])])
        self.t = np.asarray(cfg.shift_m, dtype=np.float64)

    # -- helpers --
    @staticmethod
    def _stamp(grid: np.ndarray, res: float, x: float, y: float, r: float, value) -> None:
        ny, nx = grid.shape
        i0, i1 = max(0, int((x - r) / res)), min(nx, int((x + r) / res) + 2)
        j0, j1 = max(0, int((y - r) / res)), min(ny, int((y + r) / res) + 2)
        if i0 >= i1 or j0 >= j1:
            return
        xs = (np.arange(i0, i1) + 0.5) * res
        ys = (np.arange(j0, j1) + 0.5) * res
        d = np.hypot(xs[None, :] - x, ys[:, None] - y)
        sub = grid[j0:j1, i0:i1]
        sub[d < r] = value

    def _holes(self, rng: np.random.Generator, n: int) -> np.ndarray | None:
        if n <= 0:
            return None
        bw, bh = self.cfg.before_size
        grid = np.zeros((int(math.ceil(bh / self.hole_res)) + 1,
                         int(math.ceil(bw / self.hole_res)) + 1), dtype=bool)
        for k in range(n):
            r = rng.uniform(1.5, 3.0)
            if k % 3 == 0 and self.changes:  # on a change edge
                c = self.changes[int(rng.integers(len(self.changes)))]
                ang = rng.uniform(0, 2 * np.pi)
                if c.get("exact_outline") and c["kind"] == "rect":  # on the rectangle's edge
                    ca, sa = np.cos(ang), np.sin(ang)
                    k = 1.0 / max(abs(ca) / c["a"], abs(sa) / c["b"])
                    t = math.radians(c["angle_deg"])
                    u, v = k * ca, k * sa
                    x = c["x"] + u * math.cos(t) - v * math.sin(t)
                    y = c["y"] + u * math.sin(t) + v * math.cos(t)
                else:
                    rr = c["r_bottom"] if c["kind"] == "cone" else min(c["a"], c["b"])
                    x, y = c["x"] + rr * np.cos(ang), c["y"] + rr * np.sin(ang)
            else:
                for _try in range(50):
                    x = rng.uniform(self.ax0 + 2, self.ax1 - 2)
                    y = rng.uniform(self.ay0 + 2, self.ay1 - 2)
                    if all(_clear_of(c, x, y, r + 1.0) if c.get("exact_outline")
                           else math.hypot(x - c["x"], y - c["y"]) > c["radius"] + r + 1.0
                           for c in self.changes):
                        break
            # irregular blob: union of three discs
            for _ in range(3):
                self._stamp(grid, self.hole_res, x + rng.uniform(-0.6, 0.6) * r,
                            y + rng.uniform(-0.6, 0.6) * r, r * rng.uniform(0.5, 0.9), True)
        return grid

    @staticmethod
    def _lookup(grid: np.ndarray, res: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        i = np.clip((x / res).astype(np.int64), 0, grid.shape[1] - 1)
        j = np.clip((y / res).astype(np.int64), 0, grid.shape[0] - 1)
        return grid[j, i]

    def terrain(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height (m) of the before epoch at local x/y."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        z = self.z0 + self.tilt[0] * (x - self.centre[0]) + self.tilt[1] * (y - self.centre[1])
        for amp, kx, ky, ph in self.waves:
            z += amp * np.cos(kx * x + ky * y + ph)
        for amp, hx, hy, sig in self.hills:
            z += amp * np.exp(-((x - hx) ** 2 + (y - hy) ** 2) / (2 * sig * sig))
        for kind, x0, y0, x1, y1, height, width in self.lines:
            reach = 3.5 * width if kind == 0 else 2.0 * width + 0.5
            m = ((x > min(x0, x1) - reach) & (x < max(x0, x1) + reach)
                 & (y > min(y0, y1) - reach) & (y < max(y0, y1) + reach))
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

    def deformation(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Doming + vertical bias of the after epoch (m) at local x/y."""
        cfg = self.cfg
        u = (x - self.c[0]) / ((self.ax1 - self.ax0) / 2.0)
        v = (y - self.c[1]) / ((self.ay1 - self.ay0) / 2.0)
        out = np.zeros_like(x)
        if cfg.doming_m:
            # +A at the centre, 0 at the edge mid-points, -A at the corners; a small cubic term
            # makes it not exactly a degree-2 polynomial
            out += cfg.doming_m * (1.0 - 0.55 * u * u - 0.45 * v * v + 0.15 * u * u * u)
        if cfg.vertical_bias_m:
            out += cfg.vertical_bias_m * (1.0 + 0.5 * u - 0.3 * v)
        return out

    # -- per-epoch sampling --
    def grid_shape(self, epoch: int) -> tuple[float, float, float, float, int, int]:
        cfg = self.cfg
        if epoch == 0:
            x0, y0, (w, h), n = 0.0, 0.0, cfg.before_size, cfg.before_points
        else:
            x0, y0 = self.ax0, self.ay0
            w, h, n = self.ax1 - self.ax0, self.ay1 - self.ay0, cfg.after_points
        nx = max(1, int(round(math.sqrt(n * w / h))))
        ny = max(1, int(round(n / nx)))
        return x0, y0, w, h, nx, ny

    def n_chunks(self, epoch: int) -> int:
        *_, nx, ny = self.grid_shape(epoch)
        rows = max(1, CHUNK_POINTS // nx)
        return (ny + rows - 1) // rows

    def chunk(self, epoch: int, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(xyz absolute (n,3) float64, class uint8) of chunk ``index`` of ``epoch`` (0 before,
        1 after as surveyed)."""
        cfg = self.cfg
        x0, y0, w, h, nx, ny = self.grid_shape(epoch)
        rows = max(1, CHUNK_POINTS // nx)
        j0, j1 = index * rows, min(ny, (index + 1) * rows)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 1 + epoch, index]))
        n = (j1 - j0) * nx
        sx, sy = w / nx, h / ny
        ii = np.tile(np.arange(nx, dtype=np.float64), j1 - j0)
        jj = np.repeat(np.arange(j0, j1, dtype=np.float64), nx)
        x = x0 + (ii + rng.random(n)) * sx
        y = y0 + (jj + rng.random(n)) * sy
        del ii, jj
        holes = self.holes[epoch]
        if holes is not None:
            keep = ~self._lookup(holes, self.hole_res, x, y)
            x, y = x[keep], y[keep]
        g = self.terrain(x, y)
        if epoch == 1:
            g += change_dz(x, y, cfg)
            g += self.deformation(x, y)
        z = g.copy()
        cls = np.full(x.shape, CLASS_GROUND, dtype=np.uint8)
        if len(self.feats):
            lab = self._lookup(self.label, self.feat_res, x, y)
            idx = np.nonzero(lab)[0]
            if idx.size:
                self._apply_features(epoch, idx, lab[idx] - 1, x, y, g, z, cls, rng)
        z += rng.normal(0.0, cfg.noise_m, z.shape) if cfg.noise_m > 0 else 0.0
        if cfg.outlier_fraction > 0:
            o = np.nonzero(rng.random(z.shape) < cfg.outlier_fraction)[0]
            kind = rng.random(o.size)
            near = rng.choice([-1.0, 1.0], o.size) * rng.uniform(0.25, 1.5, o.size)
            off = np.where(kind < 0.5, near,
                           np.where(kind < 0.85, rng.uniform(1.0, 8.0, o.size),
                                    -rng.uniform(0.5, 4.0, o.size)))
            z[o] += off
            cls[o] = CLASS_OUTLIER
        xyz = np.column_stack([x, y, z])
        del x, y, z, g
        if epoch == 1:
            # element-wise (not BLAS): results do not depend on the chunking (up to 1 ulp)
            d = xyz - self.c
            R = self.R
            xyz = np.column_stack([R[i, 0] * d[:, 0] + R[i, 1] * d[:, 1] + R[i, 2] * d[:, 2]
                                   for i in range(3)]) + (self.c + self.t)
            del d
        xyz += np.asarray(cfg.origin, dtype=np.float64)
        return xyz, cls

    def _apply_features(self, epoch, idx, k, x, y, g, z, cls, rng) -> None:
        f = self.feats[k]
        typ = f[:, 0]
        u0, v0 = x[idx] - f[:, 1], y[idx] - f[:, 2]
        ca, sa = np.cos(f[:, 3]), np.sin(f[:, 3])
        u, v = u0 * ca + v0 * sa, -u0 * sa + v0 * ca
        a = f[:, 7] if epoch else f[:, 4]
        b = f[:, 8] if epoch else f[:, 5]
        h = f[:, 9] if epoch else f[:, 6]
        rho2 = (u / a) ** 2 + (v / b) ** 2
        gi = g[idx]
        r1 = rng.random(idx.size)
        r2 = rng.random(idx.size)
        # bushes: canopy seen with probability 0.95 - 0.35 rho, else ground below
        bush = (typ == 0) & (rho2 < 1.0) & (r1 < 0.95 - 0.35 * np.sqrt(np.minimum(rho2, 1.0)))
        hb = h * np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0)) * (0.75 + 0.25 * r2)
        veg_cls = np.where(hb < 0.5, 3, np.where(hb < 2.0, 4, 5)).astype(np.uint8)
        # vehicles: flat roof at terrain(centre) + h, lower bonnet on one end
        veh = (typ == 1) & (np.abs(u) < a) & (np.abs(v) < b)
        zc = self.feat_zc[k]
        hv = zc + np.where(u > 0.55 * a, 0.62 * h, h)
        # boulders: half-ellipsoid
        bou = (typ == 2) & (rho2 < 1.0)
        hbo = gi + h * np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
        znew = np.where(bush, gi + hb, np.where(veh, np.maximum(hv, gi + 0.2),
                                                np.where(bou, hbo, gi)))
        cnew = np.where(bush, veg_cls, np.where(veh, CLASS_VEHICLE,
                                                np.where(bou, CLASS_BOULDER, CLASS_GROUND)))
        z[idx] = znew
        cls[idx] = cnew.astype(np.uint8)


# ----------------------------------------------------------------------------------------------
# public API


def _config_dict(cfg: SceneConfig) -> dict:
    d = asdict(cfg)
    if cfg.change != "excavation":  # only meaningful there; keeps older truth files identical
        d.pop("change_fraction")
    return d


def _truth(world: _World) -> dict:
    cfg = world.cfg
    fill = sum(f["volume"] for f in world.changes if f["sign"] > 0)
    cut = sum(f["volume"] for f in world.changes if f["sign"] < 0)
    o = np.asarray(cfg.origin, dtype=np.float64)
    # surveyed (absolute) -> true (absolute): p = R^T (q - o - c - t) + c + o
    T = np.eye(4)
    T[:3, :3] = world.R.T
    T[:3, 3] = (world.c + o) - world.R.T @ (o + world.c + world.t)
    features = []
    for f in world.changes:
        d = {k: (float(v) if isinstance(v, float | int) and not isinstance(v, bool) else v)
             for k, v in f.items()}
        d["x"] += float(o[0])
        d["y"] += float(o[1])
        features.append(d)
    return {
        "net": float(fill - cut),
        "cut": float(cut),
        "fill": float(fill),
        "transform": T.tolist(),
        "misalignment": {
            "center": (world.c + o).tolist(),
            "rotation_matrix": world.R.tolist(),
            "shift_m": list(cfg.shift_m),
            "rotation_deg": list(cfg.rotation_deg),
            "convention": "p_surveyed = R (p_true - center) + center + shift; "
                          "transform is its inverse (surveyed -> true), absolute coordinates",
        },
        "after_footprint": [world.ax0 + o[0], world.ay0 + o[1], world.ax1 + o[0],
                            world.ay1 + o[1]],
        "features": features,
        "crs": cfg.crs,
        "seed": world.seed,
        "config": _config_dict(cfg),
        "cell_note": (
            "net/cut/fill (m3) are exact integrals of the analytic ground change dz (piles and "
            "pit; fill = added material, cut >= 0 removed), excluding vegetation, objects, "
            "doming, vertical bias, noise and outliers. A raster estimate at cell size c "
            "differs from them only through edge discretisation (piles have sloped sides, so "
            "this is small: well below 0.5 % for c <= 1 m)."
        ),
    }


def scene_truth(seed: int = 0, config: SceneConfig | None = None) -> dict:
    """The truth dict of ``make_pair(seed, config)`` without sampling any point."""
    return _truth(_World(seed, config or SceneConfig()))


def iter_epoch(seed: int, config: SceneConfig, epoch: str
               ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (xyz absolute float64 (n,3), class uint8) chunks of one epoch ("before"/"after"),
    each at most ~1 M points; concatenated they equal ``make_pair``'s arrays."""
    world = _World(seed, config)
    e = {"before": 0, "after": 1}[epoch]
    for i in range(world.n_chunks(e)):
        yield world.chunk(e, i)


def make_pair(seed: int = 0, config: SceneConfig | None = None) -> Scene:
    """Generate a seeded pair in memory (deterministic for a given seed and config)."""
    config = config or SceneConfig()
    world = _World(seed, config)
    out = []
    for e in (0, 1):
        parts = [world.chunk(e, i) for i in range(world.n_chunks(e))]
        out.append((np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])))
    return Scene(out[0][0], out[1][0], out[0][1], out[1][1], _truth(world), config, int(seed))


def _las_header(config: SceneConfig, scale: float):
    import laspy
    import pyproj

    header = laspy.LasHeader(point_format=6, version="1.4")
    o = config.origin
    header.offsets = np.array([math.floor(o[0] / 1000.0) * 1000.0,
                               math.floor(o[1] / 1000.0) * 1000.0, math.floor(o[2])])
    header.scales = np.array([scale, scale, scale])
    header.add_crs(pyproj.CRS.from_user_input(config.crs))
    header.generating_software = "soilvolume.synthetic"
    return header


def _paths(directory, fmt: str) -> tuple[Path, Path, Path]:
    if fmt not in ("las", "laz"):
        raise ValueError(f"fmt must be 'las' or 'laz', not {fmt!r}")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    return d / f"before.{fmt}", d / f"after.{fmt}", d / "truth.json"


def _write_truth(path: Path, truth: dict) -> None:
    path.write_text(json.dumps(truth, indent=2) + "\n")


def write_pair(scene: Scene, directory, fmt: str = "las", scale: float = 0.001
               ) -> tuple[Path, Path, Path]:
    """Write ``before.<fmt>``, ``after.<fmt>`` (LAS 1.4, point format 6, CRS as WKT VLR,
    classification) and ``truth.json`` into ``directory``; return the three paths."""
    import laspy

    pb, pa, pt = _paths(directory, fmt)
    for path, xyz, cls in ((pb, scene.before, scene.before_class),
                           (pa, scene.after, scene.after_class)):
        las = laspy.LasData(_las_header(scene.config, scale))
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.classification = cls
        las.write(str(path))
    _write_truth(pt, scene.truth)
    return pb, pa, pt


def write_pair_streaming(seed: int, config: SceneConfig, directory, fmt: str = "las",
                         scale: float = 0.001) -> tuple[Path, Path, Path]:
    """Like ``write_pair(make_pair(seed, config), ...)`` but chunk by chunk, in bounded memory
    (~0.3 GB whatever the size): for pairs of tens of millions of points."""
    import laspy

    pb, pa, pt = _paths(directory, fmt)
    world = _World(seed, config)
    for e, path in ((0, pb), (1, pa)):
        header = _las_header(config, scale)
        with laspy.open(str(path), mode="w", header=header) as writer:
            for i in range(world.n_chunks(e)):
                xyz, cls = world.chunk(e, i)
                rec = laspy.ScaleAwarePointRecord.zeros(len(cls), header=header)
                rec.x, rec.y, rec.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
                rec.classification = cls
                writer.write_points(rec)
                del xyz, cls, rec
    _write_truth(pt, _truth(world))
    return pb, pa, pt

