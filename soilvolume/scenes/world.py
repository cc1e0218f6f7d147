"""The world of one (seed, config): terrain, features, vegetation, objects, holes and the GPS
misalignment, and the points of each epoch generated chunk by chunk."""

from __future__ import annotations

import math

import numpy as np

from .config import CLASS_BOULDER, CLASS_GROUND, CLASS_OUTLIER, CLASS_VEHICLE, SceneConfig
from .features import _after_box, _change_features, _clear_of, change_dz
from .hazards import dry, meadow_row, reached, water_levels
from .nuisances import CROP, PATCH, boulder, bush, categories, colours, extra_features, returns, vehicle

CHUNK_POINTS = 1_000_000  # points per generation chunk (fixed: results never depend on the caller)


class _World:
    """Terrain, features, holes and misalignment of one (seed, config): everything that is not
    per-point randomness. Built from its own RNG stream so epochs/chunks are independent."""

    def __init__(self, seed: int, cfg: SceneConfig):
        self.cfg = cfg
        self.seed = int(seed)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0]))
        self.ax0, self.ay0, self.ax1, self.ay1 = _after_box(cfg)
        self.changes = _change_features(cfg, self.seed)
        self._init_terrain(rng)
        self._init_features(rng)
        self.hole_res = 0.1  # occlusion holes, per epoch
        self.holes = [self._holes(rng, cfg.holes) for _ in range(2)]
        self._init_misalignment()
        self.water = water_levels(self) if cfg.water_m > 0 else []

    def _init_terrain(self, rng: np.random.Generator) -> None:
        """Tilt, long waves, hills, roughness, ditches, berm and mounds (``rng``'s first draws)."""
        cfg = self.cfg
        bw, bh = cfg.before_size
        acx, acy = (self.ax0 + self.ax1) / 2.0, (self.ay0 + self.ay1) / 2.0
        self.z0 = rng.uniform(58.0, 66.0)
        self.tilt = rng.uniform(-0.02, 0.02, 2)
        self.centre = (bw / 2.0, bh / 2.0)
        waves = []
        for amp_lo, amp_hi, wl_lo, wl_hi, n in ((0.5, 1.5, 60.0, 200.0, 3), (0.02, 0.08, 2.0, 12.0, 14)):
            for _ in range(n):
                th = rng.uniform(0, 2 * np.pi)
                k = 2 * np.pi / rng.uniform(wl_lo, wl_hi)
                waves.append((rng.uniform(amp_lo, amp_hi), k * np.cos(th), k * np.sin(th), rng.uniform(0, 2 * np.pi)))
        self.waves = np.array(waves)
        self.waves[:3, 0] *= cfg.relief
        self.hills = np.column_stack(
            [rng.uniform(-2.5, 3.0, 4), rng.uniform(0, bw, 4), rng.uniform(0, bh, 4), rng.uniform(10.0, 30.0, 4)]
        )
        self.hills[:, 0] *= cfg.relief
        aw, ah = self.ax1 - self.ax0, self.ay1 - self.ay0
        th0 = rng.uniform(0, np.pi)
        lines = []  # (kind, x0, y0, x1, y1, height, width) ; kind 0 ditch (gaussian), 1 berm
        for kind, ang in ((0, th0), (0, th0 + rng.uniform(1.0, 2.1)), (1, th0 + rng.uniform(0.5, 1.0))):
            px = acx + rng.uniform(-0.3, 0.3) * aw
            py = acy + rng.uniform(-0.3, 0.3) * ah
            half = rng.uniform(25.0, 50.0)
            dx, dy = np.cos(ang) * half, np.sin(ang) * half
            height = -rng.uniform(0.5, 1.0) if kind == 0 else rng.uniform(0.6, 1.2)
            width = rng.uniform(0.6, 1.2) if kind == 0 else rng.uniform(1.2, 2.0)
            lines.append((kind, px - dx, py - dy, px + dx, py + dy, height, width))
        self.lines = np.array(lines)
        nm = 30
        self.mounds = np.column_stack(
            [
                rng.uniform(0.15, 0.5, nm) * rng.choice([-1, 1], nm),
                rng.uniform(self.ax0 - 10, self.ax1 + 10, nm),
                rng.uniform(self.ay0 - 10, self.ay1 + 10, nm),
                rng.uniform(1.0, 3.0, nm),
            ]
        )

    def _init_features(self, rng: np.random.Generator) -> None:
        """Non-ground features (bushes, vehicles, boulders, the config's extra kinds), placed
        non-overlapping and away from the change, and their label grid."""
        cfg = self.cfg
        bw, bh = cfg.before_size
        aw, ah = self.ax1 - self.ax0, self.ay1 - self.ay0
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

        def place(n: int, inside_after: bool, make, rng=rng) -> bool:
            ok = False
            for _ in range(n):
                ok = False
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
                        ok = True
                        break
            return ok

        if cfg.vegetation:
            place(int(bw * bh / 600), False, lambda: bush(rng))
            place(int(aw * ah / 250), True, lambda: bush(rng))
        if cfg.objects:
            place(5, True, lambda: vehicle(rng))
            place(3, False, lambda: vehicle(rng))
            place(12, True, lambda: boulder(rng))
            place(10, False, lambda: boulder(rng))
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
            self._stamp(self.label, self.feat_res, f[1], f[2], f[10] + self.feat_res, k + 1)

    def _init_misalignment(self) -> None:
        """The GPS misalignment (local frame): ``p_s = R (p - c) + c + t``."""
        cfg = self.cfg
        acx, acy = (self.ax0 + self.ax1) / 2.0, (self.ay0 + self.ay1) / 2.0
        roll, pitch, yaw = np.radians(cfg.rotation_deg)
        rx = np.array([[1, 0, 0], [0, np.cos(roll), -np.sin(roll)], [0, np.sin(roll), np.cos(roll)]])
        ry = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0, np.cos(pitch)]])
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
        sub[(d < r) & (sub == 0)] = value  # features never overlap, bar the meadow under them

    def _holes(self, rng: np.random.Generator, n: int) -> np.ndarray | None:
        if n <= 0:
            return None
        bw, bh = self.cfg.before_size
        grid = np.zeros((int(math.ceil(bh / self.hole_res)) + 1, int(math.ceil(bw / self.hole_res)) + 1), dtype=bool)
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
                    if all(
                        _clear_of(c, x, y, r + 1.0)
                        if c.get("exact_outline")
                        else math.hypot(x - c["x"], y - c["y"]) > c["radius"] + r + 1.0
                        for c in self.changes
                    ):
                        break
            # irregular blob: union of three discs
            for _ in range(3):
                self._stamp(
                    grid,
                    self.hole_res,
                    x + rng.uniform(-0.6, 0.6) * r,
                    y + rng.uniform(-0.6, 0.6) * r,
                    r * rng.uniform(0.5, 0.9),
                    True,
                )
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
        if self.cfg.slope_deg:
            z += math.tan(math.radians(self.cfg.slope_deg)) * (x - self.centre[0])
        for amp, kx, ky, ph in self.waves:
            z += amp * np.cos(kx * x + ky * y + ph)
        for amp, hx, hy, sig in self.hills:
            z += amp * np.exp(-((x - hx) ** 2 + (y - hy) ** 2) / (2 * sig * sig))
        for kind, x0, y0, x1, y1, height, width in self.lines:
            reach = 3.5 * width if kind == 0 else 2.0 * width + 0.5
            m = (
                (x > min(x0, x1) - reach)
                & (x < max(x0, x1) + reach)
                & (y > min(y0, y1) - reach)
                & (y < max(y0, y1) + reach)
            )
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

    def chunk(self, epoch: int, index: int, signals: bool = False) -> tuple:
        """(xyz absolute (n,3) float64, class uint8) of chunk ``index`` of ``epoch`` (0 before,
        1 after as surveyed); with ``signals`` also a dict of the per-point fields the config's
        ``signals`` writes (``red``/``green``/``blue``, ``return_number``/``number_of_returns``;
        the classes are zeroed where the survey carries none)."""
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
            lab = self._lookup(self.label, self.feat_res, x, y)
            idx = np.nonzero(lab)[0]
            if idx.size:
                self._apply_features(epoch, idx, lab[idx] - 1, x, y, g, z, cls, rng)
                bare = fresh & (cls >= 3) & (cls <= 5)  # no grass on fresh soil
                z[bare], cls[bare] = g[bare], CLASS_GROUND
        z += rng.normal(0.0, cfg.noise_m, z.shape) if cfg.noise_m > 0 else 0.0
        o = np.empty(0, np.int64)
        if cfg.outlier_fraction > 0:
            o = np.nonzero(rng.random(z.shape) < cfg.outlier_fraction)[0]
            kind = rng.random(o.size)
            near = rng.choice([-1.0, 1.0], o.size) * rng.uniform(0.25, 1.5, o.size)
            off = np.where(
                kind < 0.5, near, np.where(kind < 0.85, rng.uniform(1.0, 8.0, o.size), -rng.uniform(0.5, 4.0, o.size))
            )
            z[o] += off
            cls[o] = CLASS_OUTLIER
        xyz = np.column_stack([x, y, z])
        del x, y, z, g
        if epoch == 1:
            # element-wise (not BLAS): results do not depend on the chunking (up to 1 ulp)
            d = xyz - self.c
            R = self.R
            xyz = np.column_stack([R[i, 0] * d[:, 0] + R[i, 1] * d[:, 1] + R[i, 2] * d[:, 2] for i in range(3)]) + (
                self.c + self.t
            )
            del d
        xyz += np.asarray(cfg.origin, dtype=np.float64)
        if not signals:
            return xyz, cls
        return (xyz, *self._signals(epoch, index, cls, o, lab, fresh))

    def _signals(self, epoch: int, index: int, cls, stray, lab, fresh) -> tuple[np.ndarray, dict]:
        """(LAS classes as the survey carries them, other per-point fields) of a chunk."""
        cfg = self.cfg
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 11 + epoch, index]))
        mask = np.zeros(cls.shape, bool)
        mask[stray] = True
        cat = categories(cls, mask)
        fields: dict = {}
        if cfg.signals == "rgb":
            rgb = colours(cat, lab - 1, fresh, cfg, rng)
            fields.update(red=rgb[:, 0], green=rgb[:, 1], blue=rgb[:, 2])
        if cfg.signals in ("lidar", "returns"):
            fields["return_number"], fields["number_of_returns"] = returns(cat, lab > 0, rng)
        keep = cfg.signals in ("class", "lidar")
        return (cls if keep else np.zeros_like(cls)), fields

    def _apply_features(self, epoch, idx, k, x, y, g, z, cls, rng) -> None:
        f = self.feats[k]
        typ = f[:, 0]
        u0, v0 = x[idx] - f[:, 1], y[idx] - f[:, 2]
        ca, sa = np.cos(f[:, 3]), np.sin(f[:, 3])
        u, v = u0 * ca + v0 * sa, -u0 * sa + v0 * ca
        a = f[:, 7] if epoch else f[:, 4]
        b = f[:, 8] if epoch else f[:, 5]
        h = f[:, 9] if epoch else f[:, 6]
        with np.errstate(divide="ignore", invalid="ignore"):  # a vehicle absent from this epoch: 0 x 0
            rho2 = np.nan_to_num((u / a) ** 2 + (v / b) ** 2, nan=np.inf)
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
        # grass patches (ellipses) and a crop field (rectangle): canopy seen with 0.85 / 0.75
        box = (np.abs(u) < a) & (np.abs(v) < b)
        low = ((typ == PATCH) & (rho2 < 1.0) & (r1 < 0.85)) | ((typ == CROP) & box & (r1 < 0.75))
        bush |= low
        hb = np.where(low, h * (0.7 + 0.6 * r2), hb)
        veg_cls = np.where(hb < 0.5, 3, np.where(hb < 2.0, 4, 5)).astype(np.uint8)
        znew = np.where(bush, gi + hb, np.where(veh, np.maximum(hv, gi + 0.2), np.where(bou, hbo, gi)))
        cnew = np.where(bush, veg_cls, np.where(veh, CLASS_VEHICLE, np.where(bou, CLASS_BOULDER, CLASS_GROUND)))
        z[idx] = znew
        cls[idx] = cnew.astype(np.uint8)
