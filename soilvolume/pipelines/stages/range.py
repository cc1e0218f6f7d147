"""filters.range with ``Dimension[lo:hi]`` limits and filters.assign with ``Dimension = number``:
the forms of the project's own pipelines (``Classification[2:2]``, ``Classification = 0``); the
other forms (open or negated ranges, WHERE clauses) need PDAL."""

from __future__ import annotations

import re

import numpy as np

from .view import PointView, StageContext

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"\s*([A-Za-z_]\w*)\s*\[\s*({_NUM})?\s*:\s*({_NUM})?\s*\]\s*")
_VALUE = re.compile(rf"\s*([A-Za-z_]\w*)\s*=\s*({_NUM})\s*")


def _passing(view: PointView, text: str, ctx: StageContext) -> tuple[str, np.ndarray]:
    """(stored dimension name, mask of the points within) of one ``Dimension[lo:hi]`` range."""
    m = _RANGE.fullmatch(text)
    if not m:
        raise ctx.error(f"range '{text.strip()[:40]}' needs PDAL (without it only 'Dimension[lo:hi]')")
    name, lo, hi = m.groups()
    key = view.dim(name)
    if key is None:
        raise ctx.error(f"invalid dimension name '{name}' (the points have: {', '.join(view.arrays)})")
    values, ok = view.arrays[key], np.ones(len(view), dtype=bool)
    if lo is not None:
        ok &= values >= float(lo)
    if hi is not None:
        ok &= values <= float(hi)
    return key, ok


def filter_range(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """The points passing ``limits``: ranges on one dimension ORed, different dimensions ANDed."""
    limits = [part for text in ctx.strings(opts, "limits") for part in text.split(",")]
    if not limits:
        raise ctx.error("option 'limits' is required")
    by_dim: dict[str, np.ndarray] = {}
    for text in limits:
        key, hit = _passing(view, text, ctx)
        by_dim[key] = by_dim[key] | hit if key in by_dim else hit
    return view.take(np.logical_and.reduce(list(by_dim.values())))


def assign(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """``value: "Dim = number"`` (no WHERE clause), applied in order."""
    for text in ctx.strings(opts, "value"):
        m = _VALUE.fullmatch(text)
        if not m:
            raise ctx.error(f"value '{text}' needs PDAL (without it only 'Dimension = number')")
        view.ensure(m.group(1))[:] = float(m.group(2))
    return view
