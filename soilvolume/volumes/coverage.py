"""Coverage: the share of the after survey's footprint (its cells, refilled ones, and its area beyond
the grid) both surveys cover, so a before survey missing part of the works never passes for "no
change"; the rest is unseen, and :func:`check` says so."""

from __future__ import annotations

import numpy as np

from .change import fill_cut
from .tolerance import moved_m3, past_net_tolerance

CAUTION_SHARE = 0.005  # unseen share of the after footprint that is named in the verdict
MAX_SHARE = 0.05  # more than this unseen: not reliable, whatever its surroundings say
RING = 3  # cells around a gap (or along the grid's edge) whose difference tells what it may hide
COUNTS = ("after_cells", "compared_cells", "before_missing_cells", "gap_ring_cells", "edge_ring_cells")
_P95 = {"abs_diff": "compared", "gap_ring": "gap_ring", "edge_ring": "edge_ring"}  # percentile: its cells


def counts(n_after, n_before, refilled, diff, shown, core=(slice(None), slice(None)), edges=(True,) * 4) -> dict:
    """Cells of the after footprint on the ``core`` (its soil cells, refilled ones, and its gaps without any
    point (``shown``: its points of any kind per cell) over soil the before saw: water, a pit it could not see
    into), compared, without before data; the |difference| p95 of the compared cells, near such gaps and along
    the ``edges`` (top, bottom, left, right) that are the grid's."""
    from scipy import ndimage

    seen = (n_after > 0) | refilled
    hidden = ndimage.binary_fill_holes(seen | (shown > 0)) & ~seen & (shown == 0) & (n_before > 0)
    footprint = seen | hidden
    compared = footprint & np.isfinite(diff)
    missing = footprint & (n_before == 0) & ~compared
    gaps = missing | hidden
    near_gap = ndimage.binary_dilation(gaps, iterations=RING) & compared if gaps.any() else gaps
    edge = np.zeros(diff.shape, bool)
    for side, cut in zip(edges, (np.s_[:RING], np.s_[-RING:], np.s_[:, :RING], np.s_[:, -RING:]), strict=True):
        edge[cut] |= side
    edge &= compared
    d = np.abs(diff[core])
    out = {k: int(m[core].sum()) for k, m in zip(COUNTS, (footprint, compared, missing, near_gap, edge), strict=True)}
    for key, m in zip(_P95, (compared, near_gap, edge), strict=True):
        out[f"{key}_p95_m"] = float(np.percentile(d[m[core]], 95)) if m[core].any() else 0.0
    return out


def combine(parts: list[dict]) -> dict:
    """:func:`counts` of tiles added up (each percentile weighted by the cells behind it)."""
    out = {k: int(sum(p[k] for p in parts)) for k in COUNTS}
    for key, cells in _P95.items():
        w = np.array([p[f"{cells}_cells"] for p in parts], float)
        v = np.array([p[f"{key}_p95_m"] for p in parts], float)
        out[f"{key}_p95_m"] = float(np.sum(w * v) / w.sum()) if w.sum() > 0 else 0.0
    return out


def summary(cells: dict, cell_area: float, beyond_m2: float, lod_m: float, outside: dict | None = None) -> dict:
    """report.json's ``coverage``; what could hide unseen: the area times the |difference| p95 around it (at least the
    LoD), or beyond the grid ``outside``."""
    footprint = cells["after_cells"] * cell_area + beyond_m2
    compared = cells["compared_cells"] * cell_area
    inside = max(cells["after_cells"] - cells["compared_cells"], 0) * cell_area
    floor = lod_m if np.isfinite(lod_m) else 0.0
    outside = outside or {"fill_m3": 0.0, "cut_m3": 0.0}
    shown = outside["fill_m3"] + outside["cut_m3"]
    p95 = {
        k: cells[f"{k}_p95_m"] if cells[f"{k}_cells"] else cells["abs_diff_p95_m"] for k in ("gap_ring", "edge_ring")
    }
    near = {k: max(v, floor) for k, v in p95.items()}  # the |difference| around the gaps, at least the LoD
    return {
        "after_footprint_m2": footprint,
        "compared_m2": compared,
        "compared_share": compared / footprint if footprint > 0 else 0.0,
        "before_missing_m2": cells["before_missing_cells"] * cell_area + beyond_m2,
        "after_beyond_before_extent_m2": beyond_m2,
        "unseen_m2": inside + beyond_m2,
        "unseen_volume_bound_m3": inside * near["gap_ring"] + max(beyond_m2 * near["edge_ring"], shown),
        "beyond_change_m3": outside,
        "abs_difference_p95_m": {"near_gaps": near["gap_ring"], "along_edge": near["edge_ring"]},
    }


def check(report: dict) -> tuple[str, str] | None:
    """(severity, sentence) of the unseen footprint: unreliable over :data:`MAX_SHARE` or over the net's interval (and
    twice the LoD), caution over :data:`CAUTION_SHARE` when what it could hide could move the net past its tolerance
    (the coverage line and report.json say the rest)."""
    cov = report.get("coverage")
    if not cov or cov["after_footprint_m2"] <= 0:
        return None
    unseen, share = cov["unseen_m2"], 1.0 - cov["compared_share"]
    u = report["uncertainty_m3"]
    bound, interval = cov["unseen_volume_bound_m3"], u["net"] - u.get("unseen_m3", 0.0)  # the measured part
    before = cov["before_missing_m2"] >= 0.5 * unseen
    who = "the before survey does not cover" if before else "the surveys do not both cover"
    who = "the design does not cover" if (report.get("reference") or {}).get("kind") == "surface" else who
    said = f"{who} {unseen:,.0f} m² ({share:.0%}) of the after footprint"
    noise = 2.0 * unseen * float(report["uncertainty_m3"].get("lod_m") or 0.0)  # change at noise level: none
    if share > MAX_SHARE or bound > max(interval, noise):
        out, source = cov.get("beyond_change_m3") or {}, "at the change seen around it"
        if out.get("fill_m3", 0.0) + out.get("cut_m3", 0.0) > 0.5 * bound:
            source = "from what the after survey shows beyond the before survey's edge, against its ground carried on"
        said += f": change there is not in the volumes (up to ~{bound:,.0f} m³ {source}, "
        return "unreliable", f"{said}against their ±{interval:,.1f} m³ interval without it)"
    if share > CAUTION_SHARE and past_net_tolerance(bound, moved_m3(report)):
        said += f": the volumes are for the compared {cov['compared_m2']:,.0f} m² only (the change seen around it "
        return "caution", f"{said}would make up to ~{bound:,.0f} m³ there, within their interval)"
    return None


def line(report: dict) -> str | None:
    """The summary's coverage line."""
    cov = report.get("coverage")
    if not cov:
        return None
    surface = (report.get("reference") or {}).get("kind") == "surface"
    who = ("the design covers", "the design misses") if surface else ("both surveys cover", "the before survey misses")
    text = f"coverage: {who[0]} {cov['compared_share']:.1%} of the after footprint"
    if cov["before_missing_m2"] > 0:
        text += f" ({who[1]} {cov['before_missing_m2']:,.0f} m2)"
    return text


EDGE_FIT = 10  # cells along the grid's edge the before ground beyond it is carried on from


def outside(after_reg: np.ndarray, grid, dem_b: np.ndarray | None, offset: np.ndarray) -> tuple[float, dict]:
    """(the area (m2) of the lattice's cells past the grid holding the after survey's registered points, their fill and
    cut (m3) over the before ground carried on: a plane within :data:`EDGE_FIT` of the edge)."""
    row, col, ok = grid.index(after_reg[:, :2])
    cells, inverse = np.unique(np.c_[row[~ok], col[~ok]], axis=0, return_inverse=True)
    beyond, none = float(len(cells) * grid.cell_area), {"fill_m3": 0.0, "cut_m3": 0.0}
    if ok.all() or dem_b is None or dem_b.shape != (grid.rows, grid.cols):
        return beyond, none
    xs, ys = grid.centers_local()
    edge = np.zeros(dem_b.shape, bool)  # the sides the after survey runs past
    r, c = row[~ok], col[~ok]
    sides = (np.s_[:EDGE_FIT], np.s_[-EDGE_FIT:], np.s_[:, :EDGE_FIT], np.s_[:, -EDGE_FIT:])
    for side, past in zip(sides, (r < 0, r >= grid.rows, c < 0, c >= grid.cols), strict=True):
        edge[side] |= bool(past.any())
    use = edge & np.isfinite(dem_b)
    if use.sum() < 3:
        return beyond, none
    a = np.c_[xs[use], ys[use], np.ones(int(use.sum()))]
    plane, *_ = np.linalg.lstsq(a, dem_b[use], rcond=None)
    out = after_reg[~ok]
    n = np.bincount(inverse.ravel(), minlength=len(cells)).astype(float)
    mean = {k: np.bincount(inverse.ravel(), out[:, k], minlength=len(cells)) / n for k in range(3)}
    shift = float(np.nanmedian(offset)) if np.isfinite(offset).any() else 0.0
    d = mean[2] - (plane[0] * mean[0] + plane[1] * mean[1] + plane[2]) - shift
    m3 = fill_cut(d, grid.cell_area)
    return beyond, {"fill_m3": m3["fill"], "cut_m3": m3["cut"]}
