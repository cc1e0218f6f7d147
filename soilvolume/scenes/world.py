"""The world of one (seed, config): terrain, features, vegetation, objects, holes and the GPS
misalignment, and the points of each epoch generated chunk by chunk."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from ..registration.rigid import rotation_zyx
from .config import CLASS_GROUND, CLASS_OUTLIER, SceneConfig
from .features import after_box, change_dz, change_features, clear_of
from .hazards import dry, meadow_row, occlusion_holes, reached, water_levels
from .nuisances import boulder, bush, categories, colours, extra_features, feature_points, returns, vehicle
from .terrain import Terrain

CHUNK_POINTS = 1_000_000  # points per generation chunk (fixed: results never depend on the caller)


class World:
    """Everything of one (seed, config) but per-point randomness, from its own RNG stream (so epochs
    and chunks are independent)."""

    def __init__(self, seed: int, cfg: SceneConfig):
        self.cfg = cfg
        self.seed = int(seed)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0]))
        self.ax0, self.ay0, self.ax1, self.ay1 = after_box(cfg)
        self.changes = change_features(cfg, self.seed)
        self.terrain = Terrain(rng, cfg, (self.ax0, self.ay0, self.ax1, self.ay1))
        self._init_features(rng)
        self.hole_res = 0.1  # occlusion holes, per epoch
        self.holes = [occlusion_holes(self, rng, cfg.holes) for _ in range(2)]
        acx, acy = (self.ax0 + self.ax1) / 2.0, (self.ay0 + self.ay1) / 2.0  # the GPS misalignment (local frame):
        self.R = rotation_zyx(*np.radians(cfg.rotation_deg))  # p_s = R (p - c) + c + t; roll, pitch, yaw
        self.c = np.array([acx, acy, float(self.terrain(np.array([acx]), np.array([acy]))[0])])
        self.t = np.asarray(cfg.shift_m, dtype=np.float64)
        self.water = water_levels(self) if cfg.water_m > 0 else []

    def _init_features(self, rng: np.random.Generator) -> None:
        """Non-ground features ``(type, x, y, angle, a, b, h, a2, b2, h2, rbound)`` placed apart and away
        from the change, and their label grid."""
        cfg = self.cfg
        bw, bh = cfg.before_size
        aw, ah = self.ax1 - self.ax0, self.ay1 - self.ay0
        self.feat_res = 0.25
        shape = (int(math.ceil(bh / self.feat_res)) + 1, int(math.ceil(bw / self.feat_res)) + 1)
        self.label = np.zeros(shape, dtype=np.int32)  # 0 = none, k+1 = feature k
        self._placed: list[tuple] = []  # their last field: the bounding radius
        place, feats = self._place, self._placed
        if cfg.vegetation:
            place(int(bw * bh / 600), False, lambda: bush(rng), rng)
            place(int(aw * ah / 250), True, lambda: bush(rng), rng)
        if cfg.objects:
            place(5, True, lambda: vehicle(rng), rng)
            place(3, False, lambda: vehicle(rng), rng)
            place(12, True, lambda: boulder(rng), rng)
            place(10, False, lambda: boulder(rng), rng)
        extra = np.random.default_rng(np.random.SeedSequence([self.seed, 7]))  # new kinds: own stream
        self.n_plain = len(feats)  # features after these are the config's extra kinds
        self.roles = extra_features(cfg, extra, lambda inside, params: place(1, inside, lambda: params, extra))
        if cfg.meadow > 0:  # over the works: stamped last, under every other feature
            feats.append(meadow_row(cfg, (self.ax0, self.ay0, self.ax1, self.ay1), extra))
            self.roles.append("vegetation")
        self.feats = np.array(feats, dtype=np.float64).reshape(-1, 11)
        if len(self.feats):
            self.feat_zc = self.terrain(self.feats[:, 1], self.feats[:, 2])
        for k, f in enumerate(self.feats):
            self.stamp(self.label, self.feat_res, f[1], f[2], f[10] + self.feat_res, k + 1)

    def _place(self, n: int, inside_after: bool, make, rng: np.random.Generator) -> bool:
        """Place ``n`` features ``make()`` at random (50 tries each), apart and away from the change:
        whether any was placed."""
        (bw, bh), placed = self.cfg.before_size, len(self._placed)
        for _ in range(n):
            for _try in range(50):
                if inside_after:
                    x, y = rng.uniform(self.ax0 + 1, self.ax1 - 1), rng.uniform(self.ay0 + 1, self.ay1 - 1)
                else:
                    x, y = rng.uniform(0, bw), rng.uniform(0, bh)
                params = make()
                r = params[-1]
                if (
                    r < x < bw - r
                    and r < y < bh - r
                    and all(clear_of(c, x, y, r + 2.0) for c in self.changes)
                    and all(math.hypot(x - f[1], y - f[2]) > r + f[-1] + 0.5 for f in self._placed)
                ):
                    self._placed.append((params[0], x, y) + params[1:])
                    break
        return len(self._placed) > placed

    @staticmethod
    def stamp(grid: np.ndarray, res: float, x: float, y: float, r: float, value) -> None:
        ny, nx = grid.shape
        i0, i1 = max(0, int((x - r) / res)), min(nx, int((x + r) / res) + 2)
        j0, j1 = max(0, int((y - r) / res)), min(ny, int((y + r) / res) + 2)  # (empty off the grid)
        xs = (np.arange(i0, i1) + 0.5) * res
        ys = (np.arange(j0, j1) + 0.5) * res
        d = np.hypot(xs[None, :] - x, ys[:, None] - y)
        sub = grid[j0:j1, i0:i1]
        sub[(d < r) & (sub == 0)] = value  # features never overlap, bar the meadow under them

    @staticmethod
    def lookup(grid: np.ndarray, res: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        i = np.clip((x / res).astype(np.int64), 0, grid.shape[1] - 1)
        j = np.clip((y / res).astype(np.int64), 0, grid.shape[0] - 1)
        return grid[j, i]

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

    def chunks(self, epoch: int, signals: bool = False) -> Iterator[tuple]:
        """Each :meth:`chunk` of ``epoch`` in turn."""
        *_, nx, ny = self.grid_shape(epoch)
        rows = max(1, CHUNK_POINTS // nx)
        return (self.chunk(epoch, i, signals) for i in range((ny + rows - 1) // rows))

    def chunk(self, epoch: int, index: int, signals: bool = False) -> tuple:
        """(xyz absolute (n, 3), class uint8) of chunk ``index`` of ``epoch`` (0 before, 1 after as
        surveyed); with ``signals`` also the per-point fields the config writes (classes zeroed where
        the survey carries none)."""
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
        keep = reached(self, epoch, x, y)  # occlusion holes; a before survey short of the after's east
        x, y = x[keep], y[keep]
        g = self.terrain(x, y)
        fresh = np.zeros(x.shape, bool)
        if epoch == 1:
            dz = change_dz(x, y, cfg, self.seed)
            g += dz
            g += self.deformation(x, y)
            fresh = dz != 0
            if self.water:  # no point on the water of the pits
                keep = dry(self.water, x, y, g, dz)
                x, y, g, fresh = x[keep], y[keep], g[keep], fresh[keep]
        z = g.copy()
        cls = np.full(x.shape, CLASS_GROUND, dtype=np.uint8)
        lab = np.zeros(x.shape, np.int32)
        if len(self.feats):
            lab = self.lookup(self.label, self.feat_res, x, y)
            idx = np.nonzero(lab)[0]
            if idx.size:
                feature_points(self.feats, self.feat_zc, epoch, idx, lab[idx] - 1, (x, y, g, z, cls), rng)
                bare = fresh & (cls >= 3) & (cls <= 5)  # no grass on fresh soil
                z[bare], cls[bare] = g[bare], CLASS_GROUND
        z += rng.normal(0.0, cfg.noise_m, z.shape) if cfg.noise_m > 0 else 0.0
        o = _outliers(rng, z, cls, cfg.outlier_fraction) if cfg.outlier_fraction > 0 else np.empty(0, np.int64)
        xyz = np.column_stack([x, y, z])
        del x, y, z, g
        if epoch == 1:
            xyz = self._misaligned(xyz)
        xyz += np.asarray(cfg.origin, dtype=np.float64)
        return (xyz, *self._signals(epoch, index, cls, o, lab, fresh)) if signals else (xyz, cls)

    def _misaligned(self, xyz: np.ndarray) -> np.ndarray:
        """The after points misaligned element-wise (not BLAS): the same whatever the chunking."""
        d, r = xyz - self.c, self.R
        return np.column_stack([r[i, 0] * d[:, 0] + r[i, 1] * d[:, 1] + r[i, 2] * d[:, 2] for i in range(3)]) + (
            self.c + self.t
        )

    def _signals(self, epoch: int, index: int, cls, stray, lab, fresh) -> tuple[np.ndarray, dict]:
        """(LAS classes as the survey carries them, other per-point fields) of a chunk."""
        cfg = self.cfg
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 11 + epoch, index]))
        cat = categories(cls, stray)
        fields: dict = {}
        if cfg.signals == "rgb":
            rgb = colours(cat, lab - 1, fresh, cfg, rng)
            fields.update(red=rgb[:, 0], green=rgb[:, 1], blue=rgb[:, 2])
        if cfg.signals in ("lidar", "returns"):
            fields["return_number"], fields["number_of_returns"] = returns(cat, lab > 0, rng)
        return (cls if cfg.signals in ("class", "lidar") else np.zeros_like(cls)), fields


def _outliers(rng: np.random.Generator, z: np.ndarray, cls: np.ndarray, fraction: float) -> np.ndarray:
    """Points made outliers (moved up or down, classed as such) in place: their indices."""
    o = np.nonzero(rng.random(z.shape) < fraction)[0]
    kind = rng.random(o.size)
    near = rng.choice([-1.0, 1.0], o.size) * rng.uniform(0.25, 1.5, o.size)
    off = np.where(
        kind < 0.5, near, np.where(kind < 0.85, rng.uniform(1.0, 8.0, o.size), -rng.uniform(0.5, 4.0, o.size))
    )
    z[o] += off
    cls[o] = CLASS_OUTLIER
    return o
