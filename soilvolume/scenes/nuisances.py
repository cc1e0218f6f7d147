"""What is not soil on a synthetic site, and the per-point signals a survey carries: vehicles that
moved, arrived or left, equipment that arrived, grass patches grown or mown, a crop field (their own
random stream, so pairs without them are unchanged); colour (``signals="rgb"``: soil brown or grey
with shadows, vegetation green but not saturated, vehicles painted, boulders grey); LiDAR returns
(canopy points early returns of several, the ground below the last, hard surfaces single)."""

from __future__ import annotations

import math

import numpy as np

from .config import CLASS_BOULDER, CLASS_GROUND, CLASS_VEHICLE, SceneConfig

SIGNALS = ("class", "rgb", "lidar", "returns", "none")
# feature types of the world's feature table
BUSH, VEHICLE, BOULDER, PATCH, CROP = 0, 1, 2, 3, 4
# per-point categories the colours and returns are drawn for
SOIL, GREEN, CAR, STONE, STRAY = 0, 1, 2, 3, 4
PAINT = np.array([[205, 165, 45], [215, 214, 208], [72, 74, 78], [205, 105, 40], [55, 72, 140]], float)
SOIL_RGB = {"brown": (128, 102, 78), "grey": (118, 116, 110)}
# equipment and materials that arrived (``equipment``), in turn: (name, feature type, half length, half
# width, height): boxes as vehicles, pipes as a mound
EQUIPMENT = (
    ("excavator", VEHICLE, 2.9, 1.5, 3.0),
    ("container", VEHICLE, 3.05, 1.22, 2.6),
    ("site cabin", VEHICLE, 2.2, 1.3, 2.8),
    ("truck", VEHICLE, 3.8, 1.25, 3.2),
    ("pipe stack", BOULDER, 3.0, 1.6, 1.4),
)


def vehicle_shape(rng: np.random.Generator) -> tuple[float, float, float]:
    """Half length, half width and height (m) of a vehicle (as the world's own vehicles)."""
    return rng.uniform(2.1, 2.6), rng.uniform(0.85, 1.0), rng.uniform(1.4, 1.9)


def extra_features(cfg: SceneConfig, rng: np.random.Generator, place) -> list[str]:
    """Place the config's moved, arriving and leaving vehicles, patches, crop field and equipment with
    ``place(inside_after, params)`` (False: no free spot): each placed feature's role, in order."""
    if cfg.signals not in SIGNALS:
        raise ValueError(f"unknown signals {cfg.signals!r} ({', '.join(SIGNALS)})")
    roles: list[str] = []
    for _ in range(cfg.movers):  # the same vehicle at two places: before only, then after only
        a, b, h = vehicle_shape(rng)
        r = math.hypot(a, b)
        if place(True, (VEHICLE, rng.uniform(0, np.pi), a, b, h, 0.0, 0.0, 0.0, r)):
            moved = place(True, (VEHICLE, rng.uniform(0, np.pi), 0.0, 0.0, 0.0, a, b, h, r))
            roles += ["moved", "moved"] if moved else ["left"]  # no room for its new place: it left
    for n, after in ((cfg.arrivals, True), (cfg.departures, False)):
        for _ in range(n):
            a, b, h = vehicle_shape(rng)
            shape = (0.0, 0.0, 0.0, a, b, h) if after else (a, b, h, 0.0, 0.0, 0.0)
            if place(True, (VEHICLE, rng.uniform(0, np.pi), *shape, math.hypot(a, b))):
                roles.append("arrived" if after else "left")
    grown = cfg.patch_change == "grown"
    if cfg.patch_change not in ("grown", "mown"):
        raise ValueError(f"unknown patch_change {cfg.patch_change!r} (grown, mown)")
    for _ in range(cfg.patches):
        a, b = rng.uniform(2.0, 4.5), rng.uniform(1.5, 3.5)
        tall = rng.uniform(0.2, 0.6) if grown else rng.uniform(0.3, 0.6)
        h0, h1 = (0.05, tall) if grown else (tall, 0.05)
        if place(True, (PATCH, rng.uniform(0, np.pi), a, b, h0, a, b, h1, max(a, b))):
            roles.append("vegetation")
    if cfg.crops:
        a, b = rng.uniform(8.0, 10.0), rng.uniform(5.0, 7.0)
        if place(True, (CROP, rng.uniform(-0.3, 0.3), a, b, 0.2, a, b, 0.8, math.hypot(a, b))):
            roles.append("vegetation")
    for k in range(cfg.equipment):
        _, typ, a, b, h = EQUIPMENT[k % len(EQUIPMENT)]
        j = rng.uniform(0.9, 1.1)
        if place(True, (typ, rng.uniform(0, np.pi), 0.0, 0.0, 0.0, a * j, b * j, h, math.hypot(a, b) * j)):
            roles.append("arrived")
    return roles


def categories(cls: np.ndarray, stray: np.ndarray) -> np.ndarray:
    """Per-point category (:data:`SOIL` ...) from the world's classes and the ``stray`` (outlier) points."""
    cat = np.full(cls.shape, SOIL, np.uint8)
    cat[(cls >= 3) & (cls <= 5)] = GREEN
    cat[cls == 6] = CAR
    cat[cls == 1] = STONE
    cat[stray] = STRAY
    return cat


def colours(cat: np.ndarray, feature: np.ndarray, fresh: np.ndarray, cfg: SceneConfig, rng) -> np.ndarray:
    """RGB (uint16) per point; ``feature``: each point's feature (-1 none), ``fresh``: on the works."""
    n = cat.size
    soil = np.array(SOIL_RGB.get(cfg.site_tone, SOIL_RGB["brown"]), float)
    rgb = np.broadcast_to(soil, (n, 3)).copy()
    rgb[fresh] *= np.array([0.88, 0.86, 0.85])
    green = cat == GREEN
    dry = rng.uniform(0.0, 0.5, n)[:, None]  # blended towards dry grass
    leaf = (1 - dry) * np.array([88.0, 112.0, 62.0]) + dry * np.array([140.0, 130.0, 90.0])
    mixed = rng.random(n) < 0.1  # canopy pixels blended with the soil below
    leaf = np.where(mixed[:, None], 0.3 * leaf + 0.7 * soil, leaf)
    rgb[green] = leaf[green]
    car = cat == CAR
    rgb[car] = PAINT[np.maximum(feature[car], 0) % len(PAINT)]
    rgb[cat == STONE] = (130.0, 128.0, 122.0)
    bright = 1.0 + rng.normal(0.0, 0.08, n)
    shade = rng.random(n) < 0.12
    bright[shade] *= rng.uniform(0.35, 0.7, int(shade.sum()))
    rgb = rgb * bright[:, None] + rng.normal(0.0, 5.0, (n, 3))
    return (np.clip(rgb, 0, 255) * 256).astype(np.uint16)


def returns(cat: np.ndarray, under: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """(return number, number of returns) per point: canopy mostly first of 2-3, ground ``under``
    vegetation last of 2, others single."""
    n = cat.size
    num, ret = np.ones(n, np.uint8), np.ones(n, np.uint8)
    canopy = (cat == GREEN) & (rng.random(n) >= 0.2)
    num[canopy] = rng.integers(2, 4, int(canopy.sum()))
    ground = under & (cat == SOIL)
    num[ground] = ret[ground] = 2
    return ret, num


def bush(rng: np.random.Generator) -> tuple:
    """A bush's feature parameters (type 0, grown in the after epoch)."""
    r, h = rng.uniform(0.8, 3.0), rng.uniform(0.3, 4.0)
    r2, h2 = r * 1.1, h * 1.2 + 0.1  # grown in the after epoch
    return (0, 0.0, r, r, h, r2, r2, h2, r2)


def vehicle(rng: np.random.Generator) -> tuple:
    """A vehicle's feature parameters (type 1: the same place in both epochs)."""
    a, b, h = vehicle_shape(rng)
    return (1, rng.uniform(0, np.pi), a, b, h, a, b, h, math.hypot(a, b))


def boulder(rng: np.random.Generator) -> tuple:
    """A boulder's feature parameters (type 2)."""
    a, b, h = rng.uniform(0.6, 1.5), rng.uniform(0.6, 1.5), rng.uniform(0.5, 1.3)
    return (2, rng.uniform(0, np.pi), a, b, h, a, b, h, max(a, b))


def feature_points(feats: np.ndarray, feat_zc: np.ndarray, epoch: int, idx, k, pts: tuple, rng) -> None:
    """The points ``idx`` over features ``k`` as ``epoch`` sees them: their heights ``z`` lifted off the
    ground ``g`` and classes ``cls`` set, in place (``pts``: x, y, g, z, cls)."""
    x, y, g, z, cls = pts
    f = feats[k]
    typ = f[:, 0]
    u0, v0 = x[idx] - f[:, 1], y[idx] - f[:, 2]
    ca, sa = np.cos(f[:, 3]), np.sin(f[:, 3])
    u, v = u0 * ca + v0 * sa, -u0 * sa + v0 * ca
    a, b, h = (f[:, 7:10] if epoch else f[:, 4:7]).T
    with np.errstate(divide="ignore", invalid="ignore"):  # a vehicle absent from this epoch: 0 x 0
        rho2 = np.nan_to_num((u / a) ** 2 + (v / b) ** 2, nan=np.inf)
    gi = g[idx]
    r1, r2 = rng.random(idx.size), rng.random(idx.size)
    # bushes: canopy seen with probability 0.95 - 0.35 rho, else ground below
    bush = (typ == 0) & (rho2 < 1.0) & (r1 < 0.95 - 0.35 * np.sqrt(np.minimum(rho2, 1.0)))
    hb = h * np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0)) * (0.75 + 0.25 * r2)
    # vehicles: flat roof at terrain(centre) + h, lower bonnet on one end
    veh = (typ == 1) & (np.abs(u) < a) & (np.abs(v) < b)
    zc = feat_zc[k]
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
    z[idx] = np.where(bush, gi + hb, np.where(veh, np.maximum(hv, gi + 0.2), np.where(bou, hbo, gi)))
    cls[idx] = np.where(bush, veg_cls, np.where(veh, CLASS_VEHICLE, np.where(bou, CLASS_BOULDER, CLASS_GROUND)))
