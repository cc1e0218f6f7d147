"""filters.range (PDAL range syntax) and filters.assign's ``value: "Dimension = number"``."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ...core.types import SoilVolumeError
from .view import PointView, StageContext

RANGE_OPTS = {"limits"}
ASSIGN_OPTS = {"value"}

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"\s*([A-Za-z_][A-Za-z0-9_]*)\s*(!?)\s*([\[(])\s*({_NUM})?\s*:\s*({_NUM})?\s*([\])])\s*")


@dataclass(frozen=True)
class DimRange:
    """One range: ``name[lo:hi]``; ``(``/``)`` exclude an end, ``!`` negates, ends may be empty."""

    name: str
    lo: float | None
    hi: float | None
    lo_closed: bool
    hi_closed: bool
    negate: bool

    def passes(self, v: np.ndarray) -> np.ndarray:
        ok = np.ones(v.shape, dtype=bool)
        if self.lo is not None:
            ok &= (v >= self.lo) if self.lo_closed else (v > self.lo)
        if self.hi is not None:
            ok &= (v <= self.hi) if self.hi_closed else (v < self.hi)
        return ~ok if self.negate else ok


def parse_ranges(text: str) -> list[DimRange]:
    """A comma-separated list of ranges, e.g. ``"Z[0:100],Classification![7:7]"``."""
    out, pos = [], 0
    text = text.strip()
    while pos < len(text):
        m = _RANGE.match(text, pos)
        if not m:
            raise SoilVolumeError(f"invalid range '{text[pos : pos + 40]}' (e.g. 'Classification[2:2]')")
        name, neg, lb, lo, hi, rb = m.groups()
        out.append(
            DimRange(
                name,
                None if lo is None else float(lo),
                None if hi is None else float(hi),
                lb == "[",
                rb == "]",
                neg == "!",
            )
        )
        pos = m.end()
        if pos < len(text):
            if text[pos] != ",":
                raise SoilVolumeError(f"invalid range list '{text}': ranges are separated by ','")
            pos += 1
    return out


def select(view: PointView, ranges: list[DimRange], ctx: StageContext) -> np.ndarray:
    """Points passing: ranges on one dimension are ORed, different dimensions ANDed."""
    keep = np.ones(len(view), dtype=bool)
    by_dim: dict[str, np.ndarray] = {}
    for r in ranges:
        key = view.dim(r.name)
        if key is None:
            raise ctx.error(f"invalid dimension name '{r.name}' (the points have: {', '.join(view.arrays)})")
        hit = r.passes(view.arrays[key])
        by_dim[key] = by_dim[key] | hit if key in by_dim else hit
    for hit in by_dim.values():
        keep &= hit
    return keep


def filter_range(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    limits = ctx.strings(opts, "limits")
    if not limits:
        raise ctx.error("option 'limits' is required")
    try:
        ranges = [r for text in limits for r in parse_ranges(text)]
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    return view.take(select(view, ranges, ctx))


_VALUE = re.compile(rf"\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*({_NUM})\s*")


def assign(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """``value: "Dim = number"`` (no WHERE clause), applied in order."""
    for text in ctx.strings(opts, "value"):
        m = _VALUE.fullmatch(text)
        if not m:
            raise ctx.error(f"value '{text}' needs PDAL (without it only 'Dimension = number')")
        arr = view.ensure(m.group(1))
        arr[:] = float(m.group(2))
    return view
