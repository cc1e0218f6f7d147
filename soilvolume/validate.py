"""One check of every option against its declared range (:func:`check_options`, called by the CLI, the
entry points and QGIS alike): an :class:`OptionError` naming the option, the range and the value.
``--scheduler`` is parsed once, where a run starts (:func:`schedule_of`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import fields
from typing import Any

from .core.types import SoilVolumeError
from .core.wording import opt
from .distributed.schedule import BadSchedule, Schedule, parse
from .options import Options
from .volumes.polygons import read_lines, read_polygons
from .volumes.quantities import zone_factors


class OptionError(SoilVolumeError):
    """An option value outside its allowed range; ``field`` is the :class:`Options` field name."""

    def __init__(self, field: str, reason: str) -> None:
        self.field, self.reason = field, reason
        super().__init__(f"{opt(field)}: {reason}")


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def _range_text(meta: dict[str, Any], integer: bool) -> str:
    kind = "an integer" if integer else "a finite number"
    lo, hi = meta.get("lo"), meta.get("hi")
    parts = [] if lo is None else [f"{'>' if meta.get('lo_open') else '>='} {_num(lo)}"]
    parts += [] if hi is None else [f"<= {_num(hi)}"]
    return f"must be {kind} {' and '.join(parts)}".rstrip()


def check_number(field: str, value: Any, meta: dict[str, Any], integer: bool = False) -> None:
    """Refuse a value that is not a number, not finite, or outside ``meta``'s lo..hi."""
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        raise OptionError(field, f"{_range_text(meta, integer)} (got {value!r})")
    lo, hi = meta.get("lo"), meta.get("hi")
    bad = not math.isfinite(value)
    bad = bad or (lo is not None and (value <= lo if meta.get("lo_open") else value < lo))
    bad = bad or (hi is not None and value > hi)
    if bad:
        raise OptionError(field, f"{_range_text(meta, integer)} (got {_num(value) if math.isfinite(value) else value})")


def check_options(options: Options) -> Options:
    """Every field of ``options`` against its declared choices and range; returns ``options``."""
    for f in fields(options):
        value, meta = getattr(options, f.name), f.metadata
        if value is None:
            continue
        if meta.get("choices") and value not in meta["choices"]:
            raise OptionError(f.name, f"must be one of {', '.join(meta['choices'])} (got {value!r})")
        if meta.get("lo") is not None or meta.get("hi") is not None:
            check_number(f.name, value, meta, integer=f.type in ("int", int))
        elif f.type in ("str | None", "str") and not isinstance(value, str):
            raise OptionError(f.name, f"must be text (got {value!r})")
    # the zones, stable-ground and sections files read now, before any point (their CRS is checked later)
    for name, what in (("zones", "zones file"), ("stable_mask", f"{opt('stable_mask')} file")):
        path = getattr(options, name)
        if path:
            read_polygons(path, what=what)
    if options.zones:  # a zone's own bulking or shrinkage factor: a number > 0
        zone_factors(options.zones)
    if options.sections:
        read_lines(options.sections, what=f"{opt('sections')} file")
    return options


def schedule_of(options: Options) -> Schedule | None:
    """``--scheduler`` parsed once, before any work (None for ``auto``); a bad value is an :class:`OptionError`."""
    try:
        return parse(options.scheduler)
    except BadSchedule as exc:
        raise OptionError("scheduler", exc.problem) from None


def check_bounds(bounds: Sequence[float] | None) -> tuple[float, ...] | None:
    """``xmin, ymin, xmax, ymax``: four finite numbers with xmin < xmax and ymin < ymax."""
    if bounds is None:
        return None
    b = tuple(bounds)
    if len(b) != 4 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in b):
        raise SoilVolumeError(f"--bounds: must be four finite numbers XMIN YMIN XMAX YMAX (got {b})")
    if not (b[0] < b[2] and b[1] < b[3]):
        raise SoilVolumeError(f"--bounds: XMIN must be < XMAX and YMIN < YMAX (got {' '.join(f'{v:g}' for v in b)})")
    return b
