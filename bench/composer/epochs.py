"""The points of a composed site's epochs, as its sensors return them, and its files: LAS 1.4
with the CRS (compound when a vertical datum is declared) and truth.json."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import laspy
import numpy as np

from soilvolume.scenes.nuisances import CAR, GREEN, SOIL, STONE, STRAY, colours, returns
from soilvolume.scenes.synthetic import las_header

from .objects import HIT, LIDAR_CLASS, VEGETATION, stamp_surface
from .site import Site


def _grid(site: Site, epoch: int, density: float, rng) -> tuple[np.ndarray, np.ndarray]:
    w = site.world
    if epoch == 0:
        x0, y0, (wd, ht) = 0.0, 0.0, site.config.before_size
    else:
        x0, y0, wd, ht = w.ax0, w.ay0, w.ax1 - w.ax0, w.ay1 - w.ay0
    n = max(100, int(density * wd * ht))
    nx = max(1, int(round(math.sqrt(n * wd / ht))))
    ny = max(1, int(round(n / nx)))
    x = x0 + (np.tile(np.arange(nx, dtype=float), ny) + rng.random(nx * ny)) * (wd / nx)
    y = y0 + (np.repeat(np.arange(ny, dtype=float), nx) + rng.random(nx * ny)) * (ht / ny)
    return x, y


def _objects(site: Site, epoch: int, sensor: dict, x, y, g, fresh, rng) -> tuple:
    """Heights, world categories, LAS classes, feature index and 'ground under canopy' per point."""
    n = x.size
    z, cat, feature = g.copy(), np.full(n, SOIL, np.uint8), np.full(n, -1, np.int64)
    cls, under = np.full(n, 2, np.uint8), np.zeros(n, bool)
    photo = sensor["kind"] == "photogrammetry"
    for k, obj in enumerate(site.objects):
        s = obj["before" if epoch == 0 else "after"]
        if s is None:
            continue
        base = float(site.ground(epoch, np.array([s["x"]]), np.array([s["y"]]))[0][0])
        on, top = stamp_surface(s, x, y, g, base, rng)
        veg = s["shape"] in VEGETATION
        if veg:
            on &= ~fresh  # nothing grows on fresh soil
        hit = on & (rng.random(n) < HIT.get(s["shape"], (1.0, 1.0))[0 if photo else 1])
        under |= on & ~hit
        z[hit], feature[hit] = top[hit], k
        if veg:
            above = top[hit] - g[hit]
            cat[hit], cls[hit] = GREEN, np.where(above < 0.5, 3, np.where(above < 2.0, 4, 5))
        else:
            cat[hit] = CAR if s["shape"] != "mound" else STONE
            lidar = 6 if obj["kind"] == "building" else obj.get("lidar_class", LIDAR_CLASS[s["shape"]])
            cls[hit] = lidar
    return z, cat, cls, feature, under


def _shadows(site: Site, epoch: int, x, y, rgb: np.ndarray, share: float, rng) -> None:
    """Darken the photogrammetric colours in the shadows cast by tall objects, and at random."""
    for obj in site.objects:
        s = obj["before" if epoch == 0 else "after"]
        if s is None or s["h"] < 1.0:
            continue
        dx, dy = x - s["x"], y - s["y"]
        r = math.hypot(s["a"], s["b"])
        m = (dx > 0) & (dx < r + 0.8 * s["h"]) & (np.abs(dy) < r)
        rgb[m] = (rgb[m] * 0.45).astype(np.uint16)
    dark = rng.random(x.size) < share
    rgb[dark] = (rgb[dark] * 0.5).astype(np.uint16)


def _distortions(site: Site, epoch: int, sensor: dict, x, y, z, rng) -> tuple:
    """Doming, flight-strip steps, noise and outliers; returns (x, y, z, outlier mask)."""
    w = site.world
    if sensor["doming_m"]:
        (x0, y0, x1, y1) = (0.0, 0.0, *site.config.before_size) if epoch == 0 else (w.ax0, w.ay0, w.ax1, w.ay1)
        u, v = (x - (x0 + x1) / 2) / ((x1 - x0) / 2), (y - (y0 + y1) / 2) / ((y1 - y0) / 2)
        z = z + sensor["doming_m"] * (1.0 - 0.55 * u * u - 0.45 * v * v + 0.15 * u**3)
    strips = site.desc["georef"]["strips"]
    if strips and strips["epoch"] == ("before", "after")[epoch]:
        t = math.radians(strips["angle_deg"])
        odd = np.floor((x * math.cos(t) + y * math.sin(t)) / strips["width_m"]) % 2 == 1
        sx, sy, sz = strips["step_m"]
        x, y, z = x + odd * sx, y + odd * sy, z + odd * sz
    z = z + rng.normal(0.0, sensor["noise_m"], z.shape)
    stray = rng.random(z.shape) < sensor["outliers"]
    z[stray] += np.where(rng.random(int(stray.sum())) < 0.7, rng.uniform(1.0, 15.0, int(stray.sum())), -2.0)
    return x, y, z, stray


def epoch_points(site: Site, epoch: int) -> tuple[np.ndarray, np.ndarray, dict]:
    """(xyz absolute (n, 3), LAS class, other fields) of ``epoch`` (0 before, 1 after as surveyed)."""
    sensor = site.desc["sensors"][epoch]
    rng = np.random.default_rng(np.random.SeedSequence([site.desc["seed"], 55, epoch]))
    x, y = _grid(site, epoch, sensor["density"], rng)
    keep = site.reached(epoch, x, y)
    x, y = x[keep], y[keep]
    g, dz = site.ground(epoch, x, y)
    if epoch == 1 and site.levels:
        keep = site.dry(x, y, g, dz)
        x, y, g, dz = x[keep], y[keep], g[keep], dz[keep]
    z, cat, cls, feature, under = _objects(site, epoch, sensor, x, y, g, dz != 0, rng)
    x, y, z, stray = _distortions(site, epoch, sensor, x, y, z, rng)
    cat[stray] = STRAY
    cls[stray] = np.where(rng.random(int(stray.sum())) < 0.5, 7, 1)
    xyz = np.column_stack([x, y, z])
    if epoch == 1:
        w = site.world
        xyz = (xyz - w.c) @ w.R.T + w.c + w.t
    xyz += np.asarray(site.config.origin)
    fields: dict = {}
    if sensor["signals"] == "rgb":
        rgb = colours(cat, feature, dz != 0, site.config, rng)
        _shadows(site, epoch, x, y, rgb, sensor["shadows"], rng)
        fields.update(red=rgb[:, 0], green=rgb[:, 1], blue=rgb[:, 2])
    else:
        fields["return_number"], fields["number_of_returns"] = returns(cat, under, rng)
    if not (sensor["signals"] == "lidar" and sensor["classes"]):
        cls = np.zeros_like(cls)
    return xyz, cls, fields


def write_site(site: Site, directory, scale: float = 0.001) -> tuple[Path, Path, Path]:
    """Write before.las, after.las (LAS 1.4, the CRS, the sensors' fields) and truth.json."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = (d / "before.las", d / "after.las", d / "truth.json")
    for epoch in (0, 1):
        xyz, cls, fields = epoch_points(site, epoch)
        cfg = replace(site.config, signals=site.desc["sensors"][epoch]["signals"])
        las = laspy.LasData(las_header(cfg, scale))
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.classification = cls
        for name, values in fields.items():
            las[name] = values
        las.write(str(paths[epoch]))
    paths[2].write_text(json.dumps(site.truth(), indent=2) + "\n")
    return paths
