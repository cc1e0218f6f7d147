"""Stage 3, the classification (:func:`classify`): the change areas (:mod:`.change`), what in them is not soil, the
error model's stable ground away from the change. What the volume step leaves out of the soil, and says so: moved
objects (by shape, :mod:`soilvolume.soil.objects`) out of the change areas; cells mostly of points not soil listed
with the volume they would have added; objects in one survey only left out and listed (or counted with ``--objects
count``); the class raster (``excluded.tif``) draws it all. What cannot be said to be soil or not (the change no
signal classified, what a canopy may have added under it) is a bound the interval is widened by."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy

from ..core.types import GridSpec
from ..dem.grid import EpochDEM
from ..options import Options
from ..soil.objects import Blob, find_objects, rough_cells, roughness
from .change import change_areas, part_budget
from .refill import Corrected, Refill
from .results import Epochs

SHARE = 1.0 / 3.0  # a cell belongs to a non-soil class when at least this share of its points is
MACHINE_M3 = 40.0  # an object in one survey of at most this volume may be a machine (or half a move)
# Without any signal (no classification, colour or returns) a compact change patch on unchanged
# ground (a machine, a bush, a grass patch grown or mown, or a small heap) cannot be told from soil:
# patches of at most this area and volume, and rough cells, are "unclassified". So is a
# machine-sized object in one survey only, whatever the signals (a machine that left, or soil).
# Their volume is a bound, not a random error: the interval is widened by it (the net by the
# larger of the fill and cut parts) and the verdict names it.
UNCLEAR_AREA_M2, UNCLEAR_M3 = 150.0, MACHINE_M3
PLATE_M, PLATE_AREA_M2 = 0.45, 4.0  # a fill this thin, even and sharp-edged may be a slab as well as soil
CANOPY_REACH = 2.0  # how far above the ground a canopy's points taken for soil may lift a cell (x its mean)
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
MIN_QUIET = 12  # stable cells away from the change the error model needs, else it keeps them all


@dataclass(frozen=True)
class Areas:
    """The change areas counted (what is not soil left out), the class raster, report.json's ``excluded`` (with its
    terms, :func:`exclude_nonsoil`), the stable ground."""

    fill: np.ndarray
    cut: np.ndarray
    classes: np.ndarray
    excluded: dict
    stable: np.ndarray
    counted: np.ndarray  # fill | cut: the change areas the headline sums


def classify(s: Refill, c: Corrected, epochs: Epochs, grid: GridSpec, options: Options) -> Areas:
    """The change areas, what is not soil in them, stable ground never in or next to them unless the user drew it."""
    fill, cut = change_areas(c.diff, c.lod_cell, refilled=s.filled_mask & ~s.seen_once)
    kept = exclude_nonsoil(s, c, (fill, cut), epochs, grid, options)
    quiet = c.stable & ~scipy.ndimage.binary_dilation(fill | cut, iterations=max(1, round(2.0 / grid.cell)))
    stable = quiet if not options.stable_mask and quiet.sum() >= MIN_QUIET else c.stable
    return Areas(*kept, stable, kept[0] | kept[1])


def exclude_nonsoil(
    s: Refill, c: Corrected, areas: tuple[np.ndarray, np.ndarray], epochs: Epochs, grid: GridSpec, options: Options
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(the change areas without what was left out, the class raster, report.json's ``excluded`` with the one-sigma
    terms ``sigma_m3`` and the unclassified bound ``bound_m3``): see module; ``areas``: (fill, cut) of ``s``, ``c``."""
    (fill, cut), mode, area, diff = areas, options.exclude, grid.cell_area, c.diff
    refilled = s.filled_mask & ~s.seen_once  # interpolated cells: no object's
    shares = _shares(epochs)
    found, lone, grass = _left_out(diff, areas, epochs, grid, options, refilled, shares)
    leave_out = (found.moved if mode != "none" else np.zeros(diff.shape, bool)) | lone | grass
    classified = all(e.rule is not None and e.rule.use_class for e in epochs)
    if mode != "none" and not classified:
        leave_out |= shares["objects"] >= SHARE  # one survey's object: the unclassified one shows its top, not ground
    # the share of an excluded volume it may have got wrong: less by a LAS classification (its ground is measured)
    share = CLASS_MISSED_SHARE if classified else MISSED_SHARE
    fill, cut = fill & ~leave_out, cut & ~leave_out  # what the headline counts
    # only what was left out in or beside the counted change areas can bias the headline
    near = scipy.ndimage.binary_dilation(fill | cut, iterations=NEAR_CELLS)
    classes, taken, by_class, sigma = _by_class(diff, epochs, c.offset, shares, found, near, area, share)
    report: dict = {"mode": mode, "classes": by_class}
    classes[found.moved] = 4
    classes[grass & ~(shares["vegetation"] >= SHARE)] = 1
    report["grass_patches"] = part_budget(diff, grass, area)
    sigma = {k: float(np.hypot(v, share * abs(report["grass_patches"][k]))) for k, v in sigma.items()}
    classes[found.single] = 5
    rough_area = rough(epochs, s.heights, c.stable, grid.cell, fill, cut) & ~taken & ~found.single
    classes[rough_area] = 6
    report["rough"] = part_budget(diff, rough_area, area)
    report.update(_objects(diff, found, lone, grid, mode, options.objects == "exclude" and mode != "none"))
    if mode != "none":
        moved, lone_m3 = report["moved_objects"], part_budget(diff, lone, area)
        sigma = {k: float(np.hypot(v, MOVED_SHARE * np.hypot(moved[k], lone_m3[k]))) for k, v in sigma.items()}
    report["sigma_m3"], report["bound_m3"] = sigma, bounds(diff, fill | cut, found, rough_area, epochs, area, report)
    return fill, cut, classes, report


def _left_out(diff, areas, epochs, grid: GridSpec, options: Options, refilled, shares: dict):
    """(objects found by shape, those of one survey left out, grass patches left out) of ``areas``."""
    (fill, cut), mode = areas, options.exclude
    labelled = np.any([v >= SHARE for v in shares.values()], axis=0)  # canopy beside a machine: not its walls
    surfaces = tuple(e.heights for e in epochs)  # (after, before): what a blob stood on or left
    found = find_objects(diff, fill, cut, grid.cell, refilled=refilled | labelled, surfaces=surfaces)
    drop_single = options.objects == "exclude" and mode != "none"
    lone = _lone(found) if drop_single else np.zeros(diff.shape, bool)
    after, before = (_shares((e, e))["vegetation"] < SHARE for e in epochs)  # soil measured on the surface that rose
    bare = np.where(np.nan_to_num(diff) >= 0, after, before) & ~refilled  # (a pile on a mown meadow is soil)
    grass = _grass_patches(fill | cut, shares["vegetation"] >= SHARE, bare, grid.cell_area)
    return found, lone, grass & ~found.moved & ~found.single & (mode != "none")


def _by_class(diff, epochs, offset, shares: dict, found, near, cell_area: float, share: float):
    """(class raster, point class cells, report, one-sigma terms): what cells mostly not soil would have added."""
    classes = np.where(np.isfinite(diff), 0, 255).astype(np.uint8)
    sigma = dict.fromkeys(("net", "cut", "fill"), 0.0)
    after, before = (e.all_points_height() for e in epochs)  # what the excluded points would have added:
    apparent = np.nan_to_num(after - before - np.nan_to_num(offset) - diff)
    taken, report = np.zeros(diff.shape, bool), {}
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
    """Single objects of a machine's size (:data:`OBJECT_MAX_M3`) with a box's walls (:data:`OBJECT_SLOPE`), and
    structures of any size (walls no soil stands at, on the ground around them: :attr:`Blob.structure`)."""
    ids = [
        b.label
        for b in found.single_blobs()
        if b.structure or (b.resolved and b.volume_m3 <= OBJECT_MAX_M3 and b.slope >= OBJECT_SLOPE)
    ]
    return found.single & np.isin(found.labels, ids)


def _grass_patches(change: np.ndarray, veg: np.ndarray, bare: np.ndarray, cell_area: float) -> np.ndarray:
    """Compact change patches mostly of vegetation with little ``bare`` soil: grass the colour test half missed."""
    comp, n = scipy.ndimage.label(change, structure=np.ones((3, 3), bool))
    idx = np.arange(1, n + 1)
    size = np.bincount(comp.ravel(), minlength=n + 1)[1:]
    veg_share = scipy.ndimage.sum(veg, comp, idx) / size
    soil_share = scipy.ndimage.sum(change & bare, comp, idx) / size
    keep = (size * cell_area <= UNCLEAR_AREA_M2) & (veg_share >= GRASS_VEG) & (soil_share < GRASS_SOIL)
    return np.r_[False, keep][comp]


def _shares(epochs: Epochs) -> dict[str, np.ndarray]:
    """Per class, the largest share of a cell's points (either epoch) that are of that class."""
    totals, out = [e.all_points() for e in epochs], {}
    for name, attr in (("vegetation", "veg"), ("objects", "obj"), ("other", "other")):
        parts = [(getattr(e, attr), t) for e, t in zip(epochs, totals, strict=True) if getattr(e, attr) is not None]
        shares = [np.where(t > 0, part / np.maximum(t, 1), 0.0) for part, t in parts]  # never divides by 0
        out[name] = np.maximum.reduce([np.zeros(epochs[0].counts.shape), *shares])
    return out


def _item(b: Blob, grid: GridSpec) -> dict:
    """An object for the report: absolute centroid, footprint, height, volume."""
    x, y = grid.xmin + (b.x + 0.5) * grid.cell, grid.ymax - (b.y + 0.5) * grid.cell
    kind, height = "fill" if b.sign > 0 else "cut", b.height_m
    return dict(kind=kind, x=x, y=y, area_m2=b.area_m2, height_m=height, volume_m3=b.volume_m3, moved=bool(b.partner))


def bounds(diff, counted, found, rough, epochs, cell_area: float, report: dict) -> dict:
    """The bound (m3) of the unclassified and under-canopy change in ``counted``; their sections set in ``report``."""
    signal = any(labelled(e) for e in epochs)
    unclear, n, plate = _unclear(diff, counted, found, rough, signal, cell_area)
    report["unclassified"] = {**part_budget(diff, unclear, cell_area), "count": n, "signals": signal}
    report["unclassified"]["plates_m3"] = part_budget(diff, plate, cell_area)["fill"]  # of it: slab-like plates
    kept, left = part_budget(diff, unclear & counted, cell_area), part_budget(diff, unclear & ~counted, cell_area)
    # the soil's net lies between net - (counted fill + left-out cut) and net + (counted cut + left-out fill)
    below, above = kept["fill"] + left["cut"], kept["cut"] + left["fill"]
    report["unclassified"]["net_range_m3"] = [-below, above]
    reach = np.zeros(diff.shape)  # what a canopy told by returns alone may add: each cell's |difference|, at most
    for e, o in (epochs, epochs[::-1]):  # CANOPY_REACH x its canopy or that over the other's ground
        if e.rule is None or e.rule.use_class or not e.rule.returns or e.veg is None or e.nonsoil_z is None:
            continue  # a classification is the survey's statement; colour empties such cells
        covered = (e.veg > 0) & (e.veg >= SHARE * (e.counts + e.veg)) & (e.counts > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            canopy = e.nonsoil_z / np.maximum(e.nonsoil(), 1)
            # over its own soil height (raised by the canopy points) and over the other survey's ground
            top = np.fmax(CANOPY_REACH * (canopy - e.heights), canopy - o.heights)
        reach = np.maximum(reach, np.where(covered, np.nan_to_num(np.clip(top, 0.0, None)), 0.0))
    d = np.where(counted, np.nan_to_num(diff), 0.0)
    part = np.minimum(np.abs(d), reach)
    fill, cut = float(part[d > 0].sum()) * cell_area, float(part[d < 0].sum()) * cell_area
    canopy = {"net": fill - cut, "cut": cut, "fill": fill, "area_m2": float((part > 0).sum()) * cell_area}
    report["under_canopy"] = canopy
    bound = {k: report["unclassified"][k] + canopy[k] for k in ("cut", "fill")}
    bound["net"] = max(below, above) + canopy["cut"] + canopy["fill"]
    return bound


def _unclear(diff, counted, found, rough, signal: bool, cell_area: float) -> tuple[np.ndarray, int, np.ndarray]:
    """(the change not said to be soil, its patches, the slab-like plates in it): single machine-sized objects,
    plates; without signals rough and compact."""
    small = [b.label for b in found.single_blobs() if b.volume_m3 <= UNCLEAR_M3 or not b.resolved]
    out = np.isin(found.labels, small) & found.single  # a machine, or a small or unresolved steep heap: counted or not
    plate = plates(diff, counted & (np.nan_to_num(diff) > 0), cell_area)  # a slab, or a thin layer of soil
    out |= plate
    if not signal:
        d = np.nan_to_num(diff)
        for part in (counted & (d > 0), counted & (d < 0)):
            comp, k = scipy.ndimage.label(part, structure=np.ones((3, 3), bool))
            idx = np.arange(1, k + 1)
            area = scipy.ndimage.sum(part, comp, idx) * cell_area
            vol = np.abs(scipy.ndimage.sum(d, comp, idx)) * cell_area
            keep = idx[(area <= UNCLEAR_AREA_M2) & (vol <= UNCLEAR_M3)]
            out |= np.isin(comp, keep) & part
        out |= rough & counted
    comp, n = scipy.ndimage.label(out, structure=np.ones((3, 3), bool))
    vols = np.abs(scipy.ndimage.sum(np.nan_to_num(diff), comp, np.arange(1, n + 1))) * cell_area
    return out, int((vols >= 0.5).sum()), plate  # patches of noise are no objects to name


def plates(diff: np.ndarray, fill: np.ndarray, cell_area: float) -> np.ndarray:
    """Fill patches a slab may be as well as soil: :data:`PLATE_M` thick at most, of even thickness (their core's
    interquartile range under a quarter of it) and full thickness one cell in from their edge (a thin layer's
    edges are within a cell at these resolutions, soil's as a slab's)."""
    comp, _ = scipy.ndimage.label(fill, structure=np.ones((3, 3), bool))
    out = np.zeros(fill.shape, bool)
    for k, box in enumerate(scipy.ndimage.find_objects(comp), start=1):
        blob = comp[box] == k
        if blob.sum() * cell_area < PLATE_AREA_M2:
            continue
        inner = scipy.ndimage.binary_erosion(blob, iterations=1)
        core = scipy.ndimage.binary_erosion(inner, iterations=1)
        if core.sum() < 4:
            continue
        d = np.nan_to_num(diff[box])
        q1, mid, q3 = np.percentile(d[core], [25, 50, 75])
        edge = np.median(d[inner & ~core])
        if mid <= PLATE_M and q3 - q1 <= 0.25 * mid and edge >= 0.8 * mid:
            out[box] |= blob
    return out


def rough(epochs, heights, stable, cell: float, fill: np.ndarray, cut: np.ndarray) -> np.ndarray:
    """Change on rough ground (fill: after's, cut: before's) where no signal labelled a point (they tell better)."""
    if any(labelled(e) for e in epochs):
        return np.zeros(fill.shape, bool)
    after, before = (
        rough_cells(roughness(e.spread, h, e.counts, cell), stable) for e, h in zip(epochs, heights, strict=True)
    )
    return (fill & after) | (cut & before)


def labelled(e: EpochDEM) -> bool:
    """Whether a point rule labelled the epoch (or, without its rule, any point is not soil)."""
    return (e.rule is not None and e.rule.active) or bool(e.nonsoil().any())
