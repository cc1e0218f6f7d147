"""What the volume step cannot say is soil or not: the change no signal classified (compact
patches, rough cells, machine-sized objects in one survey only) and what a canopy may have added
to the change counted under it. Their volume is a bound the interval is widened by
(:mod:`.nonsoil`)."""

from __future__ import annotations

import numpy as np
import scipy

from ..dem.grid import EpochDEM
from ..soil.rough import rough_cells, roughness

SHARE = 1.0 / 3.0  # a cell belongs to a non-soil class when at least this share of its points is
MACHINE_M3 = 40.0  # an object in one survey of at most this volume may be a machine (or half a move)
# Without any signal (no classification, colour or returns) a compact change patch on unchanged
# ground (a machine, a bush, a grass patch grown or mown, or a small heap) cannot be told from soil:
# patches of at most this area and volume, and rough cells, are "unclassified". So is a
# machine-sized object in one survey only, whatever the signals (a machine that left, or soil).
# Their volume is a bound, not a random error: the interval is widened by it (the net by the
# larger of the fill and cut parts) and the verdict names it.
UNCLEAR_AREA_M2, UNCLEAR_M3 = 150.0, MACHINE_M3
CANOPY_REACH = 2.0  # how far above the ground a canopy's points taken for soil may lift a cell (x its mean)


def bounds(diff, counted, found, rough, epochs, cell_area: float, report: dict) -> dict:
    """The bound (m3 per part) of what could not be classified or was measured under a canopy
    (``counted``: the change areas without what was left out); their sections added to
    ``report``."""
    signal = any(labelled(e) for e in epochs)
    unclear, n = _unclear(diff, counted, found, rough, signal, cell_area)
    report["unclassified"] = {**part_budget(diff, unclear, cell_area), "count": n, "signals": signal}
    kept, left = part_budget(diff, unclear & counted, cell_area), part_budget(diff, unclear & ~counted, cell_area)
    # the soil's net lies between net - (counted fill + left-out cut) and net + (counted cut + left-out fill)
    below, above = kept["fill"] + left["cut"], kept["cut"] + left["fill"]
    report["unclassified"]["net_range_m3"] = [-below, above]
    canopy = _under_canopy(diff, epochs, counted, cell_area)
    report["under_canopy"] = canopy
    bound = {k: report["unclassified"][k] + canopy[k] for k in ("cut", "fill")}
    bound["net"] = max(below, above) + canopy["cut"] + canopy["fill"]
    return bound


def _unclear(diff, counted, found, rough, signal: bool, cell_area: float) -> tuple[np.ndarray, int]:
    """The counted change the engine cannot say is soil, and in how many patches: machine-sized
    objects in one survey only; without any signal also rough cells and every compact change
    patch (see :data:`UNCLEAR_AREA_M2`)."""
    small = [b.label for b in found.single_blobs() if b.volume_m3 <= UNCLEAR_M3]
    out = np.isin(found.labels, small) & found.single  # a machine, or a small steep heap: counted or not
    if not signal:
        d = np.nan_to_num(diff)
        for part in (counted & (d > 0), counted & (d < 0)):
            comp, k = scipy.ndimage.label(part, structure=np.ones((3, 3), bool))
            if not k:
                continue
            idx = np.arange(1, k + 1)
            area = scipy.ndimage.sum(part, comp, idx) * cell_area
            vol = np.abs(scipy.ndimage.sum(d, comp, idx)) * cell_area
            keep = idx[(area <= UNCLEAR_AREA_M2) & (vol <= UNCLEAR_M3)]
            out |= np.isin(comp, keep) & part
        out |= rough & counted
    comp, n = scipy.ndimage.label(out, structure=np.ones((3, 3), bool))
    vols = np.abs(scipy.ndimage.sum(np.nan_to_num(diff), comp, np.arange(1, n + 1))) * cell_area if n else np.empty(0)
    return out, int((vols >= 0.5).sum())  # patches of noise are no objects to name


def _under_canopy(diff: np.ndarray, epochs, counted: np.ndarray, cell_area: float) -> dict:
    """What a canopy may have added to the change counted under it (m3 per part): where return
    numbers alone keep the soil points under vegetation (no classification), a cell mostly of
    canopy mixes its ground with canopy points the rule took for soil (a single return off dense
    grass), so its height may sit up to the canopy's above the ground. Each counted cell under a
    canopy in either survey adds the smaller of its |difference| and the larger of
    :data:`CANOPY_REACH` times that canopy's mean height over the cell's soil height (itself raised
    by the canopy points) and its height over the other survey's ground (mown grass: the stubble)."""
    reach = np.zeros(diff.shape)
    for e, o in (epochs, epochs[::-1]):
        if e.rule is None or e.rule.use_class or not e.rule.returns or e.veg is None or e.nonsoil_z is None:
            continue  # a classification is the survey's statement; colour empties such cells
        others = e.nonsoil()
        covered = (e.veg > 0) & (e.veg >= SHARE * (e.counts + e.veg)) & (e.counts > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            canopy = e.nonsoil_z / np.maximum(others, 1)
            # over its own soil height (raised by the canopy points) and over the other survey's ground
            top = np.fmax(CANOPY_REACH * (canopy - e.heights), canopy - o.heights)
        reach = np.maximum(reach, np.where(covered, np.nan_to_num(np.clip(top, 0.0, None)), 0.0))
    d = np.where(counted, np.nan_to_num(diff), 0.0)
    part = np.minimum(np.abs(d), reach)
    fill, cut = float(part[d > 0].sum()) * cell_area, float(part[d < 0].sum()) * cell_area
    return {"net": fill - cut, "cut": cut, "fill": fill, "area_m2": float((part > 0).sum()) * cell_area}


def rough(epochs, heights, stable, cell: float, fill: np.ndarray, cut: np.ndarray) -> np.ndarray:
    """Change cells on rough ground: fill where the after survey is rough, cut where the before is;
    only where no signal labelled any point (a classification, colour or returns say what is
    vegetation better than roughness, which curved ground on coarse cells also shows)."""
    if heights is None or stable is None or any(labelled(e) for e in epochs):
        return np.zeros(fill.shape, bool)
    out = []
    for e, h in zip(epochs, heights, strict=True):
        out.append(rough_cells(roughness(e.spread, h, e.counts, cell), stable))
    return (fill & out[0]) | (cut & out[1])


def labelled(e: EpochDEM) -> bool:
    """Whether a point rule labelled the epoch (or, without its rule, any point is not soil)."""
    return (e.rule is not None and e.rule.active) or bool(e.nonsoil().any())


def part_budget(d: np.ndarray, cells: np.ndarray, cell_area: float) -> dict:
    """Net, cut, fill (m3) and area (m2) of ``d`` over ``cells`` (NaN as 0)."""
    v = np.where(cells, np.nan_to_num(d), 0.0)
    fill, cut = float(v[v > 0].sum()) * cell_area, float(-v[v < 0].sum()) * cell_area
    return {"net": fill - cut, "cut": cut, "fill": fill, "area_m2": float(cells.sum()) * cell_area}
