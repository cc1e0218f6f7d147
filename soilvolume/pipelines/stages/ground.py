"""filters.smrf and filters.csf: Classification 2 for ground, 1 for the rest, by the project's
ground filters (:mod:`soilvolume.inputs.smrf`, :mod:`soilvolume.inputs.csf`)."""

from __future__ import annotations

import numpy as np

from ...core.types import SoilVolumeError
from ...inputs.csf import DEFAULTS, csf_classify
from ...inputs.smrf import smrf_classify
from .view import PointView, StageContext


def _last_or_only(view: PointView, ctx: StageContext) -> np.ndarray:
    """The points SMRF classifies: last and single returns (all when the returns are not known)."""
    n = len(view)
    rn_key, nr_key = view.dim("ReturnNumber"), view.dim("NumberOfReturns")
    if rn_key is None or nr_key is None:
        return np.ones(n, dtype=bool)
    rn = view.arrays[rn_key].astype(np.int64)
    nr = view.arrays[nr_key].astype(np.int64)
    zero = (rn == 0) | (nr == 0)
    if zero.all():
        return np.ones(n, dtype=bool)
    if zero.any():
        raise ctx.error("some NumberOfReturns or ReturnNumber values are 0, but not all")
    return ((rn == nr) & (nr > 1)) | (nr == 1)


def smrf(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """SMRF on the last and single returns, with PDAL's options and defaults."""
    cell = ctx.number(opts, "cell", 1.0, positive=True)
    params = {
        "cell": cell,
        "slope": ctx.number(opts, "slope", 0.15),
        "window": ctx.number(opts, "window", 18.0 * cell, positive=True),
        "threshold": ctx.number(opts, "threshold", 0.5),
        "scalar": ctx.number(opts, "scalar", 1.25),
    }
    cls = view.ensure("Classification")
    if len(view) == 0:
        return view
    use = _last_or_only(view, ctx)
    if not use.any():
        raise ctx.error("no returns to process")
    idx = np.flatnonzero(use)
    ground = smrf_classify(*(view.arrays[d][idx] for d in "XYZ"), **params)
    cls[idx] = np.where(ground, 2, 1).astype(cls.dtype)
    return view


def csf(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The cloth simulation filter on every point."""
    params = {  # numbers > 0 (rigidness checked below) of the type of their default
        key: type(value)(ctx.number(opts, key, value, positive=key != "rigidness"))
        for key, value in DEFAULTS.items()
        if key != "smooth"
    }
    params["smooth"] = bool(opts.get("smooth", DEFAULTS["smooth"]))
    if params["rigidness"] not in (1, 2, 3):
        raise ctx.error("'rigidness' must be 1, 2 or 3")
    cls = view.ensure("Classification")
    if len(view) == 0:
        return view
    try:
        ground = csf_classify(view.arrays["X"], view.arrays["Y"], view.arrays["Z"], **params)
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    cls[:] = np.where(ground, 2, 1).astype(cls.dtype)
    return view
