"""The stockpile inventory's inputs and results: a pile's toe polygon, the base it is measured
from, and each pile's volume with its interval, warnings and tonnage (frozen: results between
steps are never changed in place)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from ..core.types import SoilVolumeError

#: bases computed from the toe heights (the heights along the polygon's boundary)
TOE_BASES = ("triangulated", "plane", "lowest", "average", "highest")
#: toe bases that follow the toe line, whose spread measures how much the base choice moves a volume
FOLLOWING = ("triangulated", "plane")
DEFAULT_BASE = "triangulated"


class PileError(SoilVolumeError, ValueError):
    """A pile, its polygon, its density or its base cannot be used (one line naming it)."""


@dataclass(frozen=True)
class Pile:
    """One pile to measure: its toe polygon (shapely, in the survey's local frame, metres), its
    name (or feature id) and its bulk density (t/m3; None: no tonnage unless one is given)."""

    polygon: BaseGeometry
    name: str = ""
    density: float | None = None


@dataclass(frozen=True)
class Base:
    """The surface a pile's volume is measured from: ``kind`` one of :data:`TOE_BASES`,
    ``elevation`` (a level ``z``, local metres) or ``surface`` (a height array on the survey's
    grid, local metres, NaN where unknown)."""

    kind: str = DEFAULT_BASE
    z: float | None = None
    surface: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def label(self) -> str:
        """How the base is written in outputs: ``triangulated``, ``elevation:12.5``, ``surface``."""
        return f"elevation:{self.z:g}" if self.kind == "elevation" else self.kind


def parse_base(text: str, surface: np.ndarray | None = None) -> Base:
    """The :class:`Base` of an option value ``triangulated|plane|lowest|average|highest|
    elevation:Z|surface[:NAME]``; ``surface`` needs the height array ``surface``."""
    kind, _, arg = text.strip().partition(":")
    kind = kind.lower()
    if kind in TOE_BASES and not arg:
        return Base(kind)
    if kind == "elevation":
        try:
            z = float(arg)
        except ValueError:
            raise PileError(f"base '{text}': elevation:Z needs a number Z (metres)") from None
        if not math.isfinite(z):
            raise PileError(f"base '{text}': the elevation is not a finite number")
        return Base("elevation", z=z)
    if kind == "surface":
        if surface is None:
            raise PileError(f"base '{text}': surface needs a base raster on the survey's grid")
        return Base("surface", surface=np.asarray(surface, dtype=np.float64))
    raise PileError(f"base '{text}': use one of {', '.join(TOE_BASES)}, elevation:Z or surface:DEM")


def checked_density(density: float | None, name: str = "") -> float | None:
    """``density`` (t/m3) if None or a finite number above 0, else a :class:`PileError` naming
    the pile ``name`` (none: the density given for every pile)."""
    if density is None:
        return None
    what = f"pile '{name}': density" if name else "density"
    try:
        value = float(density)
    except (TypeError, ValueError):
        raise PileError(f"{what} '{density}' is not a number (t/m3)") from None
    if not math.isfinite(value) or value <= 0:
        raise PileError(f"{what} must be above 0 t/m3, not {density}")
    return value


def checked_polygon(polygon: BaseGeometry | None, name: str) -> BaseGeometry:
    """``polygon`` if it is a valid, non-empty Polygon or MultiPolygon with an area, else a
    :class:`PileError` saying why."""
    if polygon is None or polygon.is_empty:
        raise PileError(f"pile '{name}': the polygon is empty")
    if polygon.geom_type not in ("Polygon", "MultiPolygon"):
        raise PileError(f"pile '{name}': a {polygon.geom_type} is not a polygon")
    if not np.isfinite(shapely.get_coordinates(polygon)).all():
        raise PileError(f"pile '{name}': the polygon has a coordinate that is not a number")
    if not polygon.is_valid:
        raise PileError(f"pile '{name}': the polygon is not valid ({shapely.is_valid_reason(polygon)})")
    if polygon.area <= 0:
        raise PileError(f"pile '{name}': the polygon has no area")
    return polygon


@dataclass(frozen=True)
class PileVolume:
    """One pile's inventory line. Volumes in m3 above the base inside the polygon: ``fill_m3``
    above the base, ``cut_m3`` below it, ``volume_m3`` = fill - cut; ``interval_m3`` the 95 %
    interval (point noise, toe noise and the spread of :data:`FOLLOWING` bases, ``base_spread_m3``);
    ``by_base_m3`` the volume over each toe base; ``toe_rise_m`` how much the toe's plane rises
    across the pile; ``tonnes`` and ``tonnes_interval`` from ``density`` (t/m3) when one is known."""

    name: str
    polygon: BaseGeometry
    base: str
    volume_m3: float
    interval_m3: tuple[float, float]
    fill_m3: float
    cut_m3: float
    area_m2: float
    max_height_m: float
    base_spread_m3: float
    by_base_m3: dict[str, float]
    toe_rise_m: float
    empty_share: float
    warnings: tuple[str, ...] = ()
    density: float | None = None
    tonnes: float | None = None
    tonnes_interval: tuple[float, float] | None = None


@dataclass(frozen=True)
class Inventory:
    """Every pile of one survey: ``found`` when the piles were found in the survey (no polygons
    given); ``cell_m`` the grid's cell and ``noise_m`` the heights' noise per cell on the toes."""

    piles: tuple[PileVolume, ...]
    cell_m: float
    noise_m: float
    found: bool = False

    @property
    def volume_m3(self) -> float:
        """The piles' volumes summed."""
        return float(sum(p.volume_m3 for p in self.piles))
