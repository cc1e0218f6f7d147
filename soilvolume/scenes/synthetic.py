"""Seeded synthetic before/after pairs with a KNOWN soil volume change, in pure numpy: the paper's
geometry (Shao et al.): a before survey of about 158 m x 154 m, a smaller after one of 67 m x 62.7 m
inside it, in a UTM CRS (default EPSG:32654, absolute = local + ``config.origin``).
:func:`write_pair_streaming` writes pairs of any size chunk by chunk in bounded memory.

Truth: the true frame is the before survey's. The after survey is sampled on its footprint from
``terrain + dz + doming + bias`` (plus vegetation, objects, noise, outliers), then misaligned:
``p_surveyed = R (p - c) + c + shift`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``, ``c`` the after
footprint's centre on the terrain); ``truth["transform"]`` (absolute, row-major) is its inverse.
``truth["fill"]``/``["cut"]`` (>= 0, m3) and ``["net"]`` are exact integrals of the analytic ground
change ``dz(x, y)`` of the ``SceneConfig.change`` kind (features never overlap: cut is the pits,
fill the piles), excluding vegetation, objects, doming, bias, noise and outliers.

LAS classes: 2 ground (the changed ground too); 3/4/5 vegetation under 0.5 m, 2 m, above; 6
vehicles; 1 boulders AND outliers (deliberately not 7: a pipeline must reject them itself).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .config import SceneConfig
from .features import CHANGE_KINDS, change_dz, feature_area, features_dz, finish_features  # noqa: F401 (re-exported)
from .nuisances import BOULDER, VEHICLE
from .world import World


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
        return change_dz(np.asarray(x) - o[0], np.asarray(y) - o[1], self.config, self.seed)


def _config_dict(cfg: SceneConfig) -> dict:
    """The config without the newer fields at their defaults, nor ``change_fraction`` (only meaningful
    for an excavation): older truth files stay identical."""
    d, plain = asdict(cfg), asdict(SceneConfig())
    skip = {k for k in NEWER_FIELDS if d[k] == plain[k]} | (
        {"change_fraction"} if cfg.change != "excavation" else set()
    )
    return {k: v for k, v in d.items() if k not in skip}


NEWER_FIELDS = ("signals", "movers", "arrivals", "departures", "patches", "patch_change", "crops")
NEWER_FIELDS += ("slope_deg", "site_tone", "water_m", "equipment", "meadow", "vertical_datum", "overlap", "works")


def _objects(world: World) -> list[dict]:
    """The vehicles and equipment in one epoch only (moved, arrived or left), their approximate volume."""
    o = world.cfg.origin
    out = []
    for f, role in zip(world.feats[world.n_plain :], world.roles, strict=True):
        if f[0] not in (VEHICLE, BOULDER) or role == "vegetation":
            continue
        before = f[6] > 0
        a, b, h = (f[4], f[5], f[6]) if before else (f[7], f[8], f[9])
        if f[0] == BOULDER:  # a stack of pipes: a half-ellipsoid
            area, volume = math.pi * a * b, 2.0 / 3.0 * math.pi * a * b * h
        else:
            area, volume = 4 * a * b, 2 * a * b * h * (1.55 + 0.45 * 0.62)
        out.append(
            {
                "epoch": "before" if before else "after",
                "role": role,
                "x": float(f[1] + o[0]),
                "y": float(f[2] + o[1]),
                "area_m2": float(area),
                "volume": float(volume),
            }
        )
    return out


def world_truth(world: World) -> dict:
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
        d = {k: (float(v) if isinstance(v, float | int) and not isinstance(v, bool) else v) for k, v in f.items()}
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
        "after_footprint": [world.ax0 + o[0], world.ay0 + o[1], world.ax1 + o[0], world.ay1 + o[1]],
        "features": features,
        "one_epoch_objects": _objects(world),
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
    return world_truth(World(seed, config or SceneConfig()))


def iter_epoch(seed: int, config: SceneConfig, epoch: str) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(xyz absolute (n, 3), class uint8) chunks of one epoch ("before"/"after"): ``make_pair``'s arrays."""
    return World(seed, config).chunks({"before": 0, "after": 1}[epoch])


def make_pair(seed: int = 0, config: SceneConfig | None = None) -> Scene:
    """Generate a seeded pair in memory (deterministic for a given seed and config)."""
    config = config or SceneConfig()
    world = World(seed, config)
    (b, bc), (a, ac) = ([np.concatenate(part) for part in zip(*world.chunks(e), strict=True)] for e in (0, 1))
    return Scene(b, a, bc, ac, world_truth(world), config, int(seed))


def las_header(config: SceneConfig, scale: float):
    import laspy

    header = laspy.LasHeader(point_format=7 if config.signals == "rgb" else 6, version="1.4")
    o = config.origin
    header.offsets = np.array(
        [math.floor(o[0] / 1000.0) * 1000.0, math.floor(o[1] / 1000.0) * 1000.0, math.floor(o[2])]
    )
    header.scales = np.array([scale, scale, scale])
    header.add_crs(config.declared_crs())
    header.generating_software = "soilvolume.synthetic"
    return header


def write_pair(scene: Scene, directory, fmt: str = "las") -> tuple[Path, Path, Path]:
    """Write ``before.<fmt>``, ``after.<fmt>`` (LAS 1.4, format 6, CRS, mm) and ``truth.json``: the
    paths (the scene's seed and config written chunk by chunk: the same bytes as its arrays)."""
    return write_pair_streaming(scene.seed, scene.config, directory, fmt)


def write_pair_streaming(seed: int, config: SceneConfig, directory, fmt: str = "las") -> tuple[Path, Path, Path]:
    """``write_pair(make_pair(seed, config), ...)`` chunk by chunk, in ~0.3 GB whatever the size."""
    import laspy

    if fmt not in ("las", "laz"):
        raise ValueError(f"fmt must be 'las' or 'laz', not {fmt!r}")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    pb, pa, pt = d / f"before.{fmt}", d / f"after.{fmt}", d / "truth.json"
    world = World(seed, config)
    for e, path in ((0, pb), (1, pa)):
        header = las_header(config, 0.001)
        with laspy.open(str(path), mode="w", header=header) as writer:
            for xyz, cls, fields in world.chunks(e, signals=True):
                rec = laspy.ScaleAwarePointRecord.zeros(len(cls), header=header)
                rec.x, rec.y, rec.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
                rec.classification = cls
                for name, values in fields.items():
                    rec[name] = values
                writer.write_points(rec)
                del xyz, cls, rec
    pt.write_text(json.dumps(world_truth(world), indent=2) + "\n")
    return pb, pa, pt
