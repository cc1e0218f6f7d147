"""Step 1: read both clouds, bring them into one working frame (before CRS, metres, local origin),
select ground points and crop the before cloud to the after footprint plus the radius."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyproj

from .crop import crop_mask
from .crs import WorkFrame, lonlat_of, parse_crs, to_frame, work_frame
from .io import RawPoints, read_points
from .options import Options
from .types import Cloud, SoilVolumeError

GROUND = 2


@dataclass
class Prepared:
    """Both clouds in the local working frame (absolute = xyz + origin, in ``frame.crs``)."""

    before: Cloud  # cropped to the after footprint + radius
    after: Cloud
    frame: WorkFrame
    origin: np.ndarray
    inputs: dict


def resolve_crs(raw: RawPoints, override: str | None, flag: str) -> pyproj.CRS:
    """The CRS given on the command line, else the file's header CRS."""
    crs = parse_crs(override, raw.path) or parse_crs(raw.crs_wkt, raw.path)
    if crs is None:
        raise SoilVolumeError(f"{raw.path}: the file has no CRS in its header; pass {flag} (e.g. EPSG:32654)")
    return crs


def select_ground(raw: RawPoints, mode: str, crs: pyproj.CRS | None = None) -> tuple[np.ndarray, str]:
    """Mask of the points to use, and a note: class 2 when asked for or (auto) present, or the
    SMRF ground filter (run in metres: ``crs`` gives the file's units)."""
    n = len(raw.xyz)
    has_class = raw.classification is not None and bool((raw.classification == GROUND).any())
    if mode == "none" or (mode == "auto" and not has_class):
        return np.ones(n, bool), "all points"
    if mode in ("auto", "class"):
        if not has_class:
            raise SoilVolumeError(
                f"{raw.path}: --ground class needs ground-classified (class 2) points; the file has none")
        return raw.classification == GROUND, "class 2 (ground)"
    if mode == "filter":
        from .crs import xy_unit, z_unit
        from .stages.smrf import smrf_classify

        h, v = (xy_unit(crs), z_unit(crs)) if crs is not None else (1.0, 1.0)
        x, y, z = raw.xyz[:, 0] * h, raw.xyz[:, 1] * h, raw.xyz[:, 2] * v
        return smrf_classify(x, y, z), "SMRF ground filter"
    raise SoilVolumeError(f"unknown ground mode '{mode}'")


def prepare(before: RawPoints, after: RawPoints, options: Options) -> Prepared:
    """Working frame, local origin, ground selection and the radius crop."""
    crs_b = resolve_crs(before, options.before_crs, "--before-crs")
    crs_a = resolve_crs(after, options.after_crs, "--after-crs")
    hint = lonlat_of(before.xyz, crs_b) if crs_b.is_geographic else None
    frame = work_frame(crs_b, hint)
    keep_b, note_b = select_ground(before, options.ground, crs_b)
    keep_a, note_a = select_ground(after, options.ground, crs_a)
    xyz_b = to_frame(before.xyz[keep_b], crs_b, frame, before.path)
    xyz_a = to_frame(after.xyz[keep_a], crs_a, frame, after.path)
    lo, hi = xyz_a.min(axis=0), xyz_a.max(axis=0)
    origin = np.floor(np.r_[(lo[:2] + hi[:2]) / 2, lo[2]])
    xyz_b -= origin
    xyz_a -= origin
    mask = crop_mask(xyz_b[:, :2], xyz_a[:, :2], options.radius)
    if mask.sum() < 10:
        raise SoilVolumeError(
            f"{before.path} and {after.path} do not overlap: the before cloud has "
            f"{int(mask.sum())} points within {options.radius:g} m of the after cloud's footprint "
            "(check the CRSs and --radius)"
        )
    inputs = {
        "before": _describe(before, crs_b, int(keep_b.sum()), note_b, int(mask.sum())),
        "after": _describe(after, crs_a, int(keep_a.sum()), note_a, int(keep_a.sum())),
    }
    wkt = frame.wkt
    return Prepared(
        Cloud(xyz_b[mask], origin, wkt, before.path),
        Cloud(xyz_a, origin, wkt, after.path),
        frame, origin, inputs,
    )


def _describe(raw: RawPoints, crs: pyproj.CRS, used: int, note: str, kept: int) -> dict:
    return {"path": raw.path, "points": int(len(raw.xyz)), "points_used": used,
            "points_after_crop": kept, "selection": note, "crs": crs.name,
            "crs_wkt": crs.to_wkt()}


def read_pair(before, after) -> tuple[RawPoints, RawPoints]:
    return read_points(before), read_points(after)
