"""What the volume step leaves out of the soil, and says so: objects that moved between the
surveys (found by shape, :mod:`soilvolume.soil.objects`) are taken out of the change areas;
cells whose points were mostly not soil (vegetation, objects, other by the epochs' point rules)
are listed with the apparent volume they would have added; objects in one survey only
(machines, containers, materials) are left out too and listed, or counted with
``--objects count``. The class raster (``excluded.tif``) draws all of it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy

from ..core.types import GridSpec
from ..core.wording import opt
from ..dem.grid import EpochDEM
from ..options import Options
from ..soil.objects import Blob, find_objects
from .unclassified import SHARE, UNCLEAR_AREA_M2, bounds, part_budget, rough

# excluded.tif: one byte per cell
CLASS_CODES = {
    0: "soil",
    1: "vegetation (not gridded)",
    2: "objects by classification (not gridded)",
    3: "other points: noise, water, unclassified (not gridded)",
    4: "moved object (left out of the volumes)",
    5: "object in one survey only (listed; left out or counted as chosen)",
    6: "rough change: vegetation? (counted, in the interval)",
}
MISSED_SHARE = 0.08  # one-sigma share of an excluded volume the classification may have got wrong
CLASS_MISSED_SHARE = 0.02  # the same for classes the files' own classification gave
NEAR_CELLS = 2  # ... where it was left out within this many cells of a counted change area
MOVED_SHARE = 0.05  # the same for moved objects (matched in size, height and shape)
# an object in one survey only above this volume is no machine, cabin or container (an excavator
# holds ~50 m3 under its outline, a 40 ft container 75 m3): a steep pile, counted as soil
OBJECT_MAX_M3 = 120.0
# ... and whose walls' median slope is under this (rise/run, 50 degrees) is no box: a steep heap,
# counted (piles at their angle of repose read 0.9-1.1, machines and containers 1.3-2.7)
OBJECT_SLOPE = 1.2
GRASS_VEG, GRASS_SOIL = 0.5, 1.0 / 3.0  # a change patch of vegetation: its shares of such cells and of soil


@dataclass(frozen=True)
class Exclusion:
    """The change areas without moved objects, the class raster, the report's ``excluded``
    section and the one-sigma volume terms (m3 per part) of what the classification may have
    missed or wrongly removed."""

    fill: np.ndarray
    cut: np.ndarray
    classes: np.ndarray
    report: dict
    sigma: dict
    bound: dict = field(default_factory=lambda: dict.fromkeys(("net", "cut", "fill"), 0.0))  # unclassified (m3)


def exclude_nonsoil(
    diff: np.ndarray,
    areas: tuple[np.ndarray, np.ndarray],
    epochs: tuple[EpochDEM, EpochDEM],
    offset: np.ndarray,
    grid: GridSpec,
    options: Options,
    heights: tuple[np.ndarray, np.ndarray] | None = None,
    stable: np.ndarray | None = None,
    refilled: np.ndarray | None = None,
) -> Exclusion:
    """See module; ``areas``: the change areas (fill, cut), ``epochs`` (after, before), the
    options ``exclude`` (``none``: moved objects stay counted, still listed) and ``objects``
    (``exclude``: objects in one survey only are left out too, unless ``exclude`` is ``none``);
    ``heights`` (after, before: the heights the difference is taken from) and ``stable`` ground
    give the rough cells (:mod:`soilvolume.soil.rough`): fill where the after survey is rough,
    cut where the before survey is; ``refilled``: the interpolated cells (objects are measured
    without them)."""
    (fill, cut), mode, area = areas, options.exclude, grid.cell_area
    shares = _shares(epochs)
    found, lone, grass = _left_out(diff, areas, epochs, grid, options, refilled, shares)
    leave_out = (found.moved if mode != "none" else np.zeros(diff.shape, bool)) | lone | grass
    share = _missed_share(epochs)
    # only what was left out in or beside the counted change areas can bias the headline
    near = scipy.ndimage.binary_dilation((fill | cut) & ~leave_out, iterations=NEAR_CELLS)
    classes, taken, by_class, sigma = _by_class(diff, epochs, offset, shares, found, near, area, share)
    report: dict = {"mode": mode, "classes": by_class}
    classes[found.moved] = 4
    classes[grass & ~(shares["vegetation"] >= SHARE)] = 1
    report["grass_patches"] = part_budget(diff, grass, area)
    sigma = {k: float(np.hypot(v, share * abs(report["grass_patches"][k]))) for k, v in sigma.items()}
    classes[found.single] = 5
    rough_area = rough(epochs, heights, stable, grid.cell, fill & ~leave_out, cut & ~leave_out) & ~taken & ~found.single
    classes[rough_area] = 6
    report["rough"] = part_budget(diff, rough_area, area)
    report.update(_objects(diff, found, lone, grid, mode, options.objects == "exclude" and mode != "none"))
    if mode != "none":
        moved, lone_m3 = report["moved_objects"], part_budget(diff, lone, area)
        sigma = {k: float(np.hypot(v, MOVED_SHARE * np.hypot(moved[k], lone_m3[k]))) for k, v in sigma.items()}
    bound = bounds(diff, (fill | cut) & ~leave_out, found, rough_area, epochs, area, report)
    report["sigma_m3"], report["bound_m3"] = sigma, bound
    return Exclusion(fill & ~leave_out, cut & ~leave_out, classes, report, sigma, bound)


def _left_out(diff, areas, epochs, grid: GridSpec, options: Options, refilled, shares: dict):
    """(the objects found by shape, those of one survey only left out, the grass patches left
    out) of the change ``areas`` (fill, cut)."""
    (fill, cut), mode = areas, options.exclude
    labelled = np.any([v >= SHARE for v in shares.values()], axis=0)  # canopy beside a machine: not its walls
    found = find_objects(diff, fill, cut, grid.cell, refilled=labelled if refilled is None else refilled | labelled)
    drop_single = options.objects == "exclude" and mode != "none"
    lone = _lone(found) if drop_single else np.zeros(diff.shape, bool)
    bare = _bare_top(diff, epochs, refilled)  # soil measured on the surface that rose
    grass = _grass_patches(fill | cut, shares["vegetation"] >= SHARE, bare, grid.cell_area)
    return found, lone, grass & ~found.moved & ~found.single & (mode != "none")


def _by_class(diff, epochs, offset, shares: dict, found, near, cell_area: float, share: float):
    """(the class raster, the cells of the point classes, the report's ``classes``, the
    one-sigma terms per part) of the cells mostly of points that are not soil: the apparent
    volume they would have added, a ``share`` of it near the counted change as the term."""
    classes = np.where(np.isfinite(diff), 0, 255).astype(np.uint8)
    sigma = dict.fromkeys(("net", "cut", "fill"), 0.0)
    apparent, taken, report = _apparent(diff, epochs, offset), np.zeros(diff.shape, bool), {}
    for code, name in ((2, "objects"), (1, "vegetation"), (3, "other")):
        cells = (shares[name] >= SHARE) & ~taken & ~found.moved & ~found.single
        taken |= cells
        classes[cells] = code
        report[name] = part_budget(apparent, cells, cell_area)
        part = part_budget(apparent, cells & near, cell_area)
        sigma = {k: float(np.hypot(v, share * abs(part[k]))) for k, v in sigma.items()}
    return classes, taken, report, sigma


def _objects(diff, found, lone, grid: GridSpec, mode: str, drop_single: bool) -> dict:
    """The report's ``moved_objects`` and ``single_objects`` (those of ``lone`` left out)."""
    moved = part_budget(np.where(found.moved, diff, 0.0), found.moved, grid.cell_area)
    lone_ids = set(np.unique(found.labels[lone]).tolist())
    single = found.single_blobs()
    return {
        "moved_objects": {
            **moved,
            "count": len(found.moved_blobs()) // 2,
            "excluded": mode != "none",
            "items": [_item(b, grid) for b in found.moved_blobs()],
        },
        "single_objects": {
            "count": len(single),
            "net_m3": float(sum(b.sign * b.volume_m3 for b in single)),
            "counted": not drop_single,
            "items": [{**_item(b, grid), "counted": b.label not in lone_ids} for b in single],
        },
    }


def _lone(found) -> np.ndarray:
    """The cells of the objects in one survey only of a machine's, a container's or a stack's
    size (at most :data:`OBJECT_MAX_M3`) with a box's walls (:data:`OBJECT_SLOPE`): left out of
    the headline by default."""
    ids = [b.label for b in found.single_blobs() if b.volume_m3 <= OBJECT_MAX_M3 and b.slope >= OBJECT_SLOPE]
    return found.single & np.isin(found.labels, ids)


def _bare_top(diff: np.ndarray, epochs, refilled: np.ndarray | None) -> np.ndarray:
    """Cells whose higher surface (the after survey's on a fill, the before's on a cut) was
    measured soil: a pile raised on a mown meadow is soil, whatever grew there before."""
    after, before = (_shares((e, e))["vegetation"] < SHARE for e in epochs)
    top = np.where(np.nan_to_num(diff) >= 0, after, before)
    return top if refilled is None else top & ~refilled


def _grass_patches(change: np.ndarray, veg: np.ndarray, bare: np.ndarray, cell_area: float) -> np.ndarray:
    """Compact change patches (at most :data:`UNCLEAR_AREA_M2`) mostly of cells whose points were
    vegetation (at least :data:`GRASS_VEG`) with little soil measured on the surface that rose
    (``bare``, under :data:`GRASS_SOIL`; the rest interpolated under the canopy): grass whose dry
    blades the colour test missed in a few cells, not soil (a heap of fine soil is measured soil)."""
    comp, n = scipy.ndimage.label(change, structure=np.ones((3, 3), bool))
    if n == 0:
        return np.zeros(change.shape, bool)
    idx = np.arange(1, n + 1)
    size = np.bincount(comp.ravel(), minlength=n + 1)[1:]
    soil = change & bare
    veg_share = scipy.ndimage.sum(veg, comp, idx) / size
    soil_share = scipy.ndimage.sum(soil, comp, idx) / size
    keep = (size * cell_area <= UNCLEAR_AREA_M2) & (veg_share >= GRASS_VEG) & (soil_share < GRASS_SOIL)
    return np.r_[False, keep][comp]


def _missed_share(epochs: tuple[EpochDEM, EpochDEM]) -> float:
    """The share of an excluded volume the classification may have got wrong: the files' own LAS
    classification (ground returns below a canopy are measured) less than colour or returns."""
    by_class = all(e.rule is not None and e.rule.use_class for e in epochs)
    return CLASS_MISSED_SHARE if by_class else MISSED_SHARE


def _shares(epochs: tuple[EpochDEM, EpochDEM]) -> dict[str, np.ndarray]:
    """Per class, the largest share of a cell's points (either epoch) that are of that class."""
    out = {}
    for name, attr in (("vegetation", "veg"), ("objects", "obj"), ("other", "other")):
        best = np.zeros(epochs[0].counts.shape)
        for e in epochs:
            part = getattr(e, attr)
            if part is None:
                continue
            total = e.counts + e.nonsoil()
            with np.errstate(invalid="ignore", divide="ignore"):
                best = np.maximum(best, np.where(total > 0, part / np.maximum(total, 1), 0.0))
        out[name] = best
    return out


def _apparent(diff: np.ndarray, epochs: tuple[EpochDEM, EpochDEM], offset: np.ndarray) -> np.ndarray:
    """Per cell, the difference every point would have given minus the soil's (m; 0 where
    either is unknown): what the excluded points would have added."""
    after, before = (e.all_points_height() for e in epochs)
    d = after - before - np.nan_to_num(offset)
    return np.nan_to_num(d - diff)


def _item(b: Blob, grid: GridSpec) -> dict:
    """An object for the report: absolute centroid, footprint, height, volume."""
    x = grid.xmin + (b.x + 0.5) * grid.cell
    y = grid.ymax - (b.y + 0.5) * grid.cell
    return {
        "kind": "fill" if b.sign > 0 else "cut",
        "x": x,
        "y": y,
        "area_m2": b.area_m2,
        "height_m": b.height_m,
        "volume_m3": b.volume_m3,
        "moved": bool(b.partner),
    }


def sentence(report: dict) -> list[str]:
    """Plain sentences on what was excluded and listed (for the verdict and the CLI)."""
    out = []
    m = report.get("moved_objects") or {}
    if m.get("count"):
        verb = "excluded" if m.get("excluded") else f"counted ({opt('exclude', 'none')})"
        out.append(
            f"{m['fill']:.0f} m³ of apparent fill and {m['cut']:.0f} m³ of apparent cut in {m['count']} "
            f"moved object{'s' if m['count'] > 1 else ''} {verb}"
        )
    for name, part in (report.get("classes") or {}).items():
        if part["area_m2"] > 0 and abs(part["net"]) >= 0.5:
            out.append(f"{part['net']:+.0f} m³ of apparent change on {part['area_m2']:.0f} m² of {name} excluded")
    r = report.get("rough") or {}
    if r.get("area_m2") and abs(r.get("net", 0.0)) >= 0.5:
        out.append(
            f"{r['net']:+.0f} m³ of the change is on {r['area_m2']:.0f} m² of rough ground (vegetation?) and "
            "counted: no classification, colour or returns said what it is"
        )
    g = report.get("grass_patches") or {}
    if g.get("area_m2") and abs(g.get("net", 0.0)) >= 0.5:
        out.append(
            f"{g['net']:+.0f} m³ of change on {g['area_m2']:.0f} m² of compact patches mostly of vegetation, with "
            "little soil measured in them, left out as grass"
        )
    u = report.get("unclassified") or {}
    if u.get("count") and u.get("fill", 0.0) + u.get("cut", 0.0) >= 0.5:
        out.append(
            f"{u['fill']:.0f} m³ of apparent fill and {u['cut']:.0f} m³ of apparent cut in {u['count']} compact "
            "objects or rough areas could not be classified (counted; the interval holds both readings)"
        )
    s = report.get("single_objects") or {}
    if s.get("count"):
        items = s.get("items") or []
        kept = [i for i in items if i.get("counted", s.get("counted", True))]
        left = [i for i in items if i not in kept]
        if left:
            m3 = sum(i["volume_m3"] * (1 if i["kind"] == "fill" else -1) for i in left)
            out.append(
                f"{len(left)} object{'s' if len(left) > 1 else ''} in one survey only ({m3:+.0f} m³) left out as "
                f"machines, containers or materials ({opt('objects', 'exclude')})"
            )
        if kept:
            m3 = sum(i["volume_m3"] * (1 if i["kind"] == "fill" else -1) for i in kept)
            out.append(
                f"{len(kept)} object{'s' if len(kept) > 1 else ''} in one survey only ({m3:+.0f} m³) counted: "
                "check that they are soil"
            )
    return out
