"""Objects in the difference, by shape alone: compact blobs with near-vertical walls on unchanged
ground (vehicles, containers, the seed paper's pillars). A fill blob and a cut blob alike in size,
height and shape are one object that moved (left out of the headline); an object in one survey
only is listed, left out or counted as ``objects`` says.

Soil stands under about 45 degrees, so its band between 20 % and 80 % of the height is wide; an
object's is about one mixed cell. A blob is an object when that band's width (area over
perimeter) implies a slope of at least :data:`WALL_SLOPE` or is unresolved by the cells, and it is
mostly ringed by unchanged ground. Given the two surveys' surfaces, an object stands on the ground
around it: what arrived stands on a surface level with its ring of ground, what left leaves one
(:func:`level_with_ring`); a cut below the ground around it is a pit, soil however steep its walls.
A structure (walls no soil stands at, on level ground) is an object whatever its size or
shape (a building, a fence); without the surfaces only compact blobs under :data:`MAX_AREA_M2`
and :data:`MAX_ELONGATION` are. A change area that is no object as a whole is tried core by core
(its parts above half its height): a machine that left beside the trench it dug is one area with it.
On cells coarser than :data:`MAX_SINGLE_CELL` only matching pairs are objects.

Rough cells (:func:`roughness`, :func:`rough_cells`): a canopy is a spread of heights a cell's slope
does not explain (soil is smooth at a cell's scale); used where no signal labelled any point, their
volume carried in the interval.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy

WALL_SLOPE = 1.6  # rise over run (58 degrees)
UNRESOLVED = 1.2  # walls narrower than this many cells cannot be told from vertical
MIN_HEIGHT_M = 0.4
MIN_AREA_M2 = 2.0
MAX_AREA_M2 = 150.0
MAX_ELONGATION = 7.0  # two vehicles end to end are 5; a trench across a survey 20 and more
MIN_QUIET_RING = 0.6  # share of the ring around a blob that must be unchanged ground
LEVEL_SHARE, LEVEL_MIN_M = 0.5, 0.15  # level: nearer the ring's plane than half the height (or 0.15 m)
MAX_SINGLE_CELL = 0.8  # m: on coarser cells a vehicle's walls are not seen; only moved pairs are told
# a moved object: the two blobs' ratios within these, their outlines' rise over run at least PAIR_EDGE_SLOPE
PAIR_EDGE_SLOPE = 1.0  # soil stands at 0.6-0.9 (its angle of repose); a vehicle 1.2 m tall at 0.5 m cells reads 1.1
AREA_RATIO, HEIGHT_RATIO, SHAPE_RATIO = 2.0, 1.5, 2.5
RING_HOLE = 0.2  # a blob around unseen cells of this share of its own area is a ring, not an object
_EIGHT = np.ones((3, 3), bool)
ROUGH_FACTOR = 3.0  # residual spread over this many times the stable ground's is rough
ROUGH_MIN_M = 0.05
IQR_SPREAD = 1.5  # interquartile spread (IQR / 1.349) of a sloping cell over its standard deviation, with margin
MIN_POINTS = 6  # a spread of fewer points says little


@dataclass(frozen=True)
class Blob:
    """One object blob of the difference (volumes and areas positive; ``sign`` +1 fill)."""

    sign: int
    area_m2: float
    height_m: float
    volume_m3: float
    x: float  # centroid, local frame (m)
    y: float
    elongation: float
    label: int  # its label in :attr:`Objects.labels`
    partner: int = 0  # the label of the blob it moved from or to (0: none)
    slope: float = 0.0  # median slope (rise/run) of its walls between 20 % and 80 % of its height
    on_ground: bool | None = None  # stood on or left a surface level with the ground around (None: unknown)
    edge_slope: float = 0.0  # rise over run across its half-height outline (:func:`_edge_slope`)
    resolved: bool = True  # False: on cells too coarse to tell a lone object from a steep heap (neither is said)

    @property
    def structure(self) -> bool:
        """Walls no soil stands at, on the ground around it: an object whatever its size (a roof may slope)."""
        return bool(self.on_ground) and self.edge_slope >= WALL_SLOPE


@dataclass(frozen=True)
class Objects:
    """The blobs, their label grid, the cells of moved objects and of one-survey objects."""

    blobs: tuple[Blob, ...]
    labels: np.ndarray
    moved: np.ndarray
    single: np.ndarray

    def moved_blobs(self) -> list[Blob]:
        return [b for b in self.blobs if b.partner]

    def single_blobs(self) -> list[Blob]:
        return [b for b in self.blobs if not b.partner]


def find_objects(
    diff: np.ndarray, fill: np.ndarray, cut: np.ndarray, cell: float, refilled=None, surfaces=None
) -> Objects:
    """Object blobs of the difference in the ``fill`` and ``cut`` areas, moved ones matched;
    ``refilled``: interpolated cells, in a blob's area but not its measurements; ``surfaces``: the
    (after, before) heights, whether a blob stood on the ground around it (see the module)."""
    labels = np.zeros(diff.shape, np.int32)
    blobs: list[Blob] = []
    changed, unknown = fill | cut, ~np.isfinite(diff)
    d0 = np.nan_to_num(diff)
    for sign, area in ((1, fill), (-1, cut)):
        comp, _ = scipy.ndimage.label(area, structure=_EIGHT)
        under = None if surfaces is None else surfaces[1 if sign > 0 else 0]  # arrived on before, left after
        masks = (changed, refilled, unknown, under)
        signed, cores = sign * d0, np.zeros(comp.shape, np.int32)  # a component's cores, one at a time
        for k, sl in enumerate(scipy.ndimage.find_objects(comp), 1):
            blob = _measure(signed, comp, k, sl, masks, cell, sign, len(blobs) + 1)
            for part, psl, pk, found in [(comp, sl, k, blob)] if blob else _cores(signed, comp, k, sl, cores):
                found = found or _measure(signed, part, pk, psl, masks, cell, sign, len(blobs) + 1)
                if found is not None:
                    labels[psl][part[psl] == pk] = found.label
                    blobs.append(found)
            cores[sl] = 0
    blobs = _pairs(blobs, surfaces is not None)
    if cell > MAX_SINGLE_CELL:  # too coarse to tell a lone object from a steep pile: pairs and resolved walls, and
        blobs = [_coarse(b) for b in blobs if b.partner or b.structure or b.edge_slope >= PAIR_EDGE_SLOPE]
    labels = np.where(np.isin(labels, [b.label for b in blobs]), labels, 0)
    moved = np.isin(labels, [b.label for b in blobs if b.partner]) & (labels > 0)
    moved = scipy.ndimage.binary_dilation(moved, _EIGHT) & changed  # the mixed cells at the walls
    single = (labels > 0) & ~moved
    return Objects(tuple(blobs), labels, moved, single)


def _coarse(b: Blob) -> Blob:
    """A blob on coarse cells: a pair or a structure as it is; else, with walls steeper than soil stands at, unresolved
    (a machine that left and a steep heap read alike there)."""
    return b if b.partner or b.structure else replace(b, resolved=False)


def _cores(d, comp, k, sl, part: np.ndarray) -> list[tuple]:
    """The cores of component ``k`` (no object as a whole) above half its height, labelled in ``part`` within the
    component's box (zeros elsewhere), each a candidate of its own (part, box, label, None): a machine that left
    beside the trench it dug, a cabin on a platform's edge."""
    whole = comp[sl] == k
    dd = np.where(whole, d[sl], 0.0)
    cores, n = scipy.ndimage.label(whole & (dd >= 0.5 * float(np.percentile(dd[whole], 90))), structure=_EIGHT)
    if n == 1 and (cores > 0).sum() == whole.sum():
        return []
    part[sl] = cores
    (r0, c0), out = (s.start for s in sl), []
    for j, (rows, cols) in enumerate(scipy.ndimage.find_objects(cores), 1):  # boxes within the component's
        out.append((part, (slice(rows.start + r0, rows.stop + r0), slice(cols.start + c0, cols.stop + c0)), j, None))
    return out


def _measure(d, comp, k, sl, masks, cell, sign, label) -> Blob | None:
    """The blob of component ``k`` (``d`` positive), None when no object (a ring around unseen cells,
    a pit); ``masks``: (changed, refilled or None, without a difference, the surface it
    stood on or left, or None)."""
    pad = 3
    r0, c0 = max(sl[0].start - pad, 0), max(sl[1].start - pad, 0)
    win = (slice(r0, sl[0].stop + pad), slice(c0, sl[1].stop + pad))
    changed, refilled, unknown, under = masks
    whole = comp[win] == k
    if (scipy.ndimage.binary_fill_holes(whole) & ~whole & unknown[win]).sum() > RING_HOLE * whole.sum():
        return None
    mine = whole if refilled is None else whole & ~refilled[win]
    dd = np.where(mine, d[win], 0.0)
    height = float(np.percentile(dd[mine], 90)) if mine.any() else 0.0
    if height < MIN_HEIGHT_M:
        return None
    a = cell * cell
    half = mine & (dd >= 0.5 * height)
    area = float(half.sum()) * a
    base, top = float((mine & (dd >= 0.2 * height)).sum()), float((mine & (dd >= 0.8 * height)).sum())
    edge = half & ~scipy.ndimage.binary_erosion(half, _EIGHT)
    width = (base - top) * a / max(float(edge.sum()) * cell, cell)
    boxed = width <= max(0.6 * height / WALL_SLOPE, UNRESOLVED * cell)  # walls, not a slope (a roof may slope)
    if area < MIN_AREA_M2:
        return None
    grown = scipy.ndimage.binary_dilation(whole, _EIGHT, iterations=2)
    ring = grown & ~scipy.ndimage.binary_dilation(whole, _EIGHT)
    seen = ring & ~unknown[win]  # an unmeasured cell is neither changed nor unchanged ground
    quiet = seen & ~changed[win]
    if ring.any() and (not seen.any() or float(quiet.sum()) < MIN_QUIET_RING * float(seen.sum())):
        return None
    level = None if under is None else level_with_ring(under[win], half, quiet, height)
    if level is False and sign < 0:
        return None  # a pit: below the ground around it, soil however steep its walls
    rr, cc = np.nonzero(half)
    elong = _elongation(rr, cc)
    if not level and (area > MAX_AREA_M2 or elong > MAX_ELONGATION):
        return None  # not known to stand on the ground: only compact blobs are objects
    dw = np.where(whole, d[win], 0.0)
    edge = _edge_slope(dw, half, cell)
    apart = whole & ~scipy.ndimage.binary_dilation(half, _EIGHT, iterations=2)  # low change beside it: cores first
    if not boxed and not (level and edge >= WALL_SLOPE and apart.sum() <= 0.1 * whole.sum()):
        return None
    gy, gx = np.gradient(dw, cell)  # the walls' median slope: about 1 on a pile's flank, 1.5 and more on a box's
    band = whole & (dw >= 0.2 * height) & (dw <= 0.8 * height)
    slope = float(np.median(np.hypot(gx, gy)[band])) if band.any() else height / cell  # a step: within a cell
    vol = float(dw.sum()) * a
    centre = (float(cc.mean() + c0), float(rr.mean() + r0))
    return Blob(sign, area, height, vol, *centre, elong, label, slope=slope, on_ground=level, edge_slope=edge)


def _edge_slope(d: np.ndarray, half: np.ndarray, cell: float) -> float:
    """Rise over run across a blob's half-height outline: its second ring of cells in against the first ring
    out, two cells apart (the mixed cells of a wall between them); the first ring in when none is second."""
    inner = scipy.ndimage.binary_erosion(half, _EIGHT)
    second = inner & ~scipy.ndimage.binary_erosion(inner, _EIGHT)
    first_in, run = (second, 2.0) if second.any() else (half & ~inner, 1.0)
    out = scipy.ndimage.binary_dilation(half, _EIGHT) & ~half
    low = float(np.median(np.clip(d[out], 0.0, None))) if out.any() else 0.0
    return (float(np.median(d[first_in])) - low) / (run * cell)


def level_with_ring(surface: np.ndarray, inside: np.ndarray, ring: np.ndarray, height: float) -> bool | None:
    """Whether ``surface`` over ``inside`` lies on the plane through its ``ring`` of unchanged ground, within
    :data:`LEVEL_SHARE` of ``height`` (:data:`LEVEL_MIN_M` at least); None with too little of either measured."""
    rr, cc = np.nonzero(ring & np.isfinite(surface))
    ri, ci = np.nonzero(inside & np.isfinite(surface))
    if len(rr) < 6 or len(ri) < 3:
        return None
    design = np.c_[rr, cc, np.ones(len(rr))].astype(float)
    coef, *_ = np.linalg.lstsq(design, surface[rr, cc], rcond=None)
    off = float(np.median(surface[ri, ci] - np.c_[ri, ci, np.ones(len(ri))] @ coef))
    return abs(off) <= max(LEVEL_SHARE * height, LEVEL_MIN_M)


def _elongation(rr: np.ndarray, cc: np.ndarray) -> float:
    """Ratio of the principal axes of a set of cells (1 for a disc or a square)."""
    if rr.size < 3:
        return 1.0
    ev = np.linalg.eigvalsh(np.cov(np.vstack([rr, cc]).astype(float)) + 1e-3 * np.eye(2))
    return float(np.sqrt(max(ev[1], 1e-9) / max(ev[0], 1e-9)))


def _pairs(blobs: list[Blob], surfaces: bool) -> list[Blob]:
    """Fill and cut blobs matched into moved objects, the closest matches first; given the ``surfaces``, only blobs with
    walls steeper than soil stands (:data:`PAIR_EDGE_SLOPE` at their outline: a pile is not half of a machine), and a
    cut only where the ground it left is seen level with its ring (a pit under water is not a machine's footprint)."""
    walled = [b for b in blobs if not surfaces or (b.edge_slope >= PAIR_EDGE_SLOPE and (b.on_ground or b.sign > 0))]
    fills, cuts = [b for b in walled if b.sign > 0], [b for b in walled if b.sign < 0]
    scored = []
    for f in fills:
        for c in cuts:
            ra, rh, re = f.area_m2 / c.area_m2, f.height_m / c.height_m, f.elongation / c.elongation
            if max(ra, 1 / ra) <= AREA_RATIO and max(rh, 1 / rh) <= HEIGHT_RATIO and max(re, 1 / re) <= SHAPE_RATIO:
                scored.append((abs(np.log(ra)) + abs(np.log(rh)) + 0.5 * abs(np.log(re)), f.label, c.label))
    partner: dict[int, int] = {}
    for _, f, c in sorted(scored):
        if f not in partner and c not in partner:
            partner[f], partner[c] = c, f
    return [replace(b, partner=partner.get(b.label, 0)) for b in blobs]


def roughness(spread: np.ndarray, heights: np.ndarray, counts: np.ndarray, cell: float) -> np.ndarray:
    """Per-cell spread of heights (m) beyond a slope g's (|g| c / sqrt(12), times :data:`IQR_SPREAD`
    as an interquartile spread); NaN where too few points."""
    g2 = _steepest(heights, 1) ** 2 + _steepest(heights, 0) ** 2
    planar = IQR_SPREAD**2 * g2 / 12.0  # steps are per cell: g c
    with np.errstate(invalid="ignore"):
        r = np.sqrt(np.maximum(np.square(spread) - planar, 0.0))
    return np.where(counts >= MIN_POINTS, r, np.nan)


def _steepest(h: np.ndarray, axis: int) -> np.ndarray:
    """Per cell, the larger one-sided height step along ``axis`` (a central one halves a flank at a
    break of slope)."""
    before = np.abs(np.diff(h, axis=axis, prepend=np.nan))
    after = np.abs(np.diff(h, axis=axis, append=np.nan))
    return np.nan_to_num(np.fmax(before, after))


def rough_cells(r: np.ndarray, stable: np.ndarray) -> np.ndarray:
    """Cells whose spread ``r`` is over :data:`ROUGH_FACTOR` times stable ground's (>= :data:`ROUGH_MIN_M`)."""
    ref = r[stable & np.isfinite(r)]
    level = float(np.median(ref)) if ref.size else 0.0
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(r) > max(ROUGH_FACTOR * level, ROUGH_MIN_M)
