"""Stage 4, the interval: the error model over the counted change (:mod:`.uncertainty`), the terms
beyond it by name and the bound of what no survey saw (:mod:`.holes.works`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..compensation.correction import MODES
from ..core.types import GridSpec
from ..options import Options
from .change import marginal_terms, signed_budget
from .correct import Corrected
from .holes.works import blind_change, outline_sigma
from .nonsoil import Areas
from .refill import Refill
from .results import Epochs
from .uncertainty import interp_fraction, statistic_bias, volume_uncertainty


@dataclass(frozen=True)
class Interval:
    """report.json's ``uncertainty``, the error model (for the zones) and the holes no survey saw."""

    uncertainty: dict
    model: Callable[..., dict]
    blind: dict  # report.json's ``blind``: the holes no survey saw, their bound (m3 per part)


def interval(s: Refill, c: Corrected, a: Areas, epochs: Epochs, grid: GridSpec, options: Options, moved) -> Interval:
    """The interval of the counted change; a tile's registration and correction terms are left to the tiles'
    combination."""
    area, ex = grid.cell_area, a.excluded
    d, fa, ca = c.diff[c.core], a.fill[c.core], a.cut[c.core]  # areas decided with the halo, counted on the core
    parts = {"net": fa | ca, "cut": ca, "fill": fa}
    registration = signed_budget(pose_effect(s.f_a, grid, moved)[c.core], fa, ca, area)
    marginal = marginal_terms(d, fa, ca, c.lod_cell[c.core], area)
    skews = tuple(None if e.skew is None else e.skew[c.core] for e in epochs)
    statistic = statistic_bias(skews, s.filled_mask[c.core], parts, area)
    outline = outline_sigma(c.outline[c.core], d, parts, interp_fraction(s.filled_mask), area)
    reg_in = 0.0 if c.tile else 1.0
    terms = (registration, marginal, ex["sigma_m3"], statistic)
    extra = {k: float(np.linalg.norm([reg_in * registration[k], *(t[k] for t in terms[1:])])) for k in statistic}
    extra = {k: float(np.hypot(v, outline[k])) for k, v in extra.items()}
    hidden = blind_change(c.diff, epochs, a.counted, area, s.seen_once)
    bound = {k: v + hidden["bound_m3"][k] for k, v in ex["bound_m3"].items()}
    counted = np.zeros(c.diff.shape, bool)  # the error model over the cells counted: a tile's core
    counted[c.core] = True  # (the overview has the bias)
    n_coef = 0 if c.tile else MODES[options.correction].coefficients
    run = dict(grid=grid, confidence=options.lod_confidence, counted=counted, n_coef=n_coef, bound_m3=bound)
    model = partial(volume_uncertainty, c.diff, a.stable, fills=(s.filled_mask, s.own, c.fill_sigma), **run)
    named = {"registration_m3": registration, "marginal_detections_m3": marginal, "classification_m3": terms[2]}
    named.update(statistic_m3=statistic, outline_m3=outline)
    unc = {**model(change_mask=a.counted, extra_sigma=extra), "lod_m": c.lod, **named}
    return Interval(unc, model, hidden)


def pose_effect(h_after: np.ndarray, grid: GridSpec, moved: np.ndarray | None) -> np.ndarray:
    """The difference's change (m) if the after surface moved by ``moved`` (4x4, local): -grad(H) . u horizontally."""
    if moved is None:
        return np.zeros(h_after.shape)
    x, y = grid.centers_local()
    p = np.stack([x, y, np.nan_to_num(h_after)], axis=-1)
    u = p @ moved[:3, :3].T + moved[:3, 3] - p
    gy, gx = np.gradient(h_after, grid.cell)  # rows run south: d/dy = -d/drow
    return -(gx * u[..., 0] - gy * u[..., 1])
