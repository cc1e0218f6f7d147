"""A composed site's world: the drawn description laid on the scenes' terrain and misalignment
(:class:`..world.World`), its ground in each epoch, and its exact truth."""

from __future__ import annotations

import math

import numpy as np

from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.features import features_dz
from soilvolume.scenes.hazards import dry
from soilvolume.scenes.synthetic import world_truth
from soilvolume.scenes.world import World

CRS = (("EPSG:32654", 500_000.0, 3_900_000.0), ("EPSG:32617", 420_000.0, 4_500_000.0))
CRS += (("EPSG:25832", 690_000.0, 5_330_000.0), ("EPSG:32633", 380_000.0, 6_100_000.0))


def _moved(item: dict, dx: float, dy: float) -> dict:
    return dict(item, x=item["x"] + dx, y=item["y"] + dy)


class Site:
    """The world of one drawn description: coordinates local to the before survey's box, the
    after footprint at (ax0, ay0)-(ax1, ay1) as in the scenes."""

    def __init__(self, desc: dict):
        self.desc = desc
        seed = desc["seed"]
        crs, ox, oy = CRS[seed % len(CRS)]
        g = desc["georef"]
        self.config = SceneConfig(
            before_size=tuple(desc["size"]["before"]),
            after_size=tuple(desc["size"]["after"]),
            relief=desc["terrain"]["relief"],
            slope_deg=desc["terrain"]["slope_deg"],
            change="none",
            shift_m=tuple(g["shift_m"]),
            rotation_deg=tuple(g["rotation_deg"]),
            crs=crs,
            vertical_datum=g["vertical_datum"],
            origin=(ox + 1000.0 * (seed % 97), oy + 1000.0 * (seed % 89), round(desc["z0"] - 60.0, 2)),
            overlap=desc["coverage"]["overlap"],
        )
        self.world = World(seed, self.config)
        w = self.world
        dx, dy = w.ax0, w.ay0
        self.change = [_moved(f, dx, dy) for work in desc["works"] for f in work["change"]]
        self.standing = [_moved(f, dx, dy) for work in desc["works"] for f in work["before"]]
        self.objects = []
        for o in desc["objects"]:
            if o["kind"] != "water":
                self.objects.append({**o, **{e: o[e] and _moved(o[e], dx, dy) for e in ("before", "after")}})
        self.water = [(self.change_of(o["work"]), o["depth_m"]) for o in desc["objects"] if o["kind"] == "water"]
        self.levels = [(f, self._bottom(f) + depth) for f, depth in self.water]
        rng = np.random.default_rng(np.random.SeedSequence([seed, 54]))
        self.holes = [self._holes(rng, n) for n in desc["coverage"]["holes"]]

    def change_of(self, work: int) -> dict:
        """The (first) change feature of work ``work``, local coordinates."""
        f = self.desc["works"][work]["change"][0]
        return _moved(f, self.world.ax0, self.world.ay0)

    def terrain(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The before ground without the works standing in it: the scenes' terrain and terraces."""
        z = self.world.terrain(x, y)
        ter = self.desc["terrain"]["terraces"]
        if ter:
            spacing, angle, rise, run = ter
            t = math.radians(angle)
            s = (x * math.cos(t) + y * math.sin(t)) / spacing
            w = min(run / spacing, 0.9)
            frac = s - np.floor(s)
            z = z + rise * (np.floor(s) + np.clip((frac - (1.0 - w)) / w, 0.0, 1.0))
        return z

    def ground(self, epoch: int, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ground height, soil change dz) of ``epoch`` (0 before, 1 after) at local x, y."""
        g = self.terrain(x, y) + (features_dz(x, y, self.standing) if self.standing else 0.0)
        dz = features_dz(x, y, self.change) if (epoch and self.change) else np.zeros(np.shape(x))
        return g + dz, dz

    def _bottom(self, f: dict) -> float:
        u = np.linspace(-f["radius"], f["radius"], 81)
        x, y = (a.ravel() for a in np.meshgrid(f["x"] + u, f["y"] + u))
        g, dz = self.ground(1, x, y)
        return float(np.min(g[dz < 0]))

    def dry(self, x: np.ndarray, y: np.ndarray, g: np.ndarray, dz: np.ndarray) -> np.ndarray:
        """Mask of the after points not under the water standing in pits."""
        return dry(self.levels, x, y, g, dz)

    def _holes(self, rng: np.random.Generator, n: int) -> list[tuple[float, float, float]]:
        """Occlusion holes (discs), a third of them on the edge of a work."""
        w = self.world
        out = []
        for k in range(n):
            r = float(rng.uniform(1.0, 3.5))
            if k % 3 == 0 and self.change:
                f = self.change[int(rng.integers(len(self.change)))]
                ang = rng.uniform(0, 2 * math.pi)
                rr = f["r_bottom"] if f["kind"] == "cone" else min(f["a"], f["b"])
                out.append((f["x"] + rr * math.cos(ang), f["y"] + rr * math.sin(ang), r))
            else:
                out.append((float(rng.uniform(w.ax0, w.ax1)), float(rng.uniform(w.ay0, w.ay1)), r))
        return out

    def reached(self, epoch: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Mask of the points a survey returns (holes; a before survey short of the after one)."""
        keep = np.ones(x.shape, bool)
        for hx, hy, r in self.holes[epoch]:
            keep &= np.hypot(x - hx, y - hy) >= r
        if epoch == 0 and self.config.overlap < 1.0:
            w = self.world
            keep &= x < w.ax0 + self.config.overlap * (w.ax1 - w.ax0)
        return keep

    def truth(self) -> dict:
        """truth.json: the soil's exact net/cut/fill (analytic integrals of the works; nothing
        that is not soil), the misalignment, the features and the drawn description."""
        t = world_truth(self.world)
        fill = sum(f["volume"] for f in self.change if f["sign"] > 0)
        cut = sum(f["volume"] for f in self.change if f["sign"] < 0)
        o = self.config.origin
        t.update(net=float(fill - cut), cut=float(cut), fill=float(fill), one_epoch_objects=[])
        t["features"] = [dict(f, x=f["x"] + o[0], y=f["y"] + o[1]) for f in self.change]
        t["description"] = self.desc
        t["cell_note"] = (
            "net/cut/fill (m3) are exact integrals of the analytic soil change of the works (a moved "
            "stockpile is a cut where it stood and a fill where it lies), inside the after footprint; "
            "buildings, slabs, machines, vehicles, containers, fences, pipes, people, vegetation and "
            "water are not soil and not in them."
        )
        return t
