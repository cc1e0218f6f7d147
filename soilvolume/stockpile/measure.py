"""One pile's volume above its base inside its polygon (cells weighted by the share of them the
polygon covers), its 95 % interval, its cut and fill, tonnage and the toe's warnings."""

from __future__ import annotations

import numpy as np

from .bases import base_heights, toe_base
from .coverage import Window, window_of
from .interval import base_spread, half_width, statistic_shift
from .survey import Survey, fill_linear
from .toe import Toe, toe_of
from .types import TOE_BASES, Base, Pile, PileError, PileVolume, checked_density, checked_polygon

TOE_SIGMAS = 6.0  # a toe's rise or departure beyond this many cell noises is warned about
EMPTY_WARNING = 0.05  # share of a pile's area without a measured height beyond which it is warned about


def measure_pile(survey: Survey, pile: Pile, base: Base, index: int = 0, density: float | None = None) -> PileVolume:
    """The :class:`PileVolume` of ``pile`` (feature ``index``, named ``pile N`` without a name)
    on ``survey`` above ``base``; ``density`` (t/m3) unless the pile has its own."""
    name = pile.name or f"pile {index + 1}"
    polygon = checked_polygon(pile.polygon, name)
    rho = checked_density(pile.density if pile.density is not None else density, name)
    window = window_of(polygon, survey.grid, pad=1)
    if window is None or window.share.sum() <= 0:
        raise PileError(f"pile '{name}': its polygon lies outside the survey")
    known = np.isfinite(window.of(survey.heights))
    area = float(window.share.sum() * survey.grid.cell_area)
    empty = float(window.share[~known].sum() / window.share.sum())
    if empty >= 1.0:
        raise PileError(f"pile '{name}': the survey has no height inside its polygon")
    toe = toe_of(polygon, survey)
    if toe is None:
        raise PileError(f"pile '{name}': its toe line lies outside the survey")
    h = fill_linear(window.of(survey.heights), window.of(survey.filled))
    volumes = {k: _volume(h - toe_base(k, toe, window.x, window.y), window, survey) for k in TOE_BASES}
    d = h - base_heights(base, toe, window)
    if not np.isfinite(d[window.share > 0]).all():
        raise PileError(f"pile '{name}': the base surface has no height over part of its polygon")
    fill, cut = _sums(d, window, survey)
    spread = base_spread(volumes, fill - cut, base, toe_rise(toe) <= TOE_SIGMAS * toe.noise)
    shift = statistic_shift(window, survey.grid.cell_area, window.of(survey.errors.offset))
    half = half_width(base, toe, window, survey.grid.cell_area, window.of(survey.sigma), spread + shift)
    vol = fill - cut
    warnings = toe_warnings(toe) + _empty_warning(empty)
    return PileVolume(
        name=name,
        polygon=polygon,
        base=base.label,
        volume_m3=vol,
        interval_m3=(vol - half, vol + half),
        fill_m3=fill,
        cut_m3=cut,
        area_m2=area,
        max_height_m=float(np.max(d[window.share > 0])),
        base_spread_m3=spread,
        by_base_m3=volumes,
        toe_rise_m=toe_rise(toe),
        empty_share=empty,
        warnings=warnings,
        density=rho,
        tonnes=None if rho is None else vol * rho,
        tonnes_interval=None if rho is None else ((vol - half) * rho, (vol + half) * rho),
    )


def _sums(d: np.ndarray, window: Window, survey: Survey) -> tuple[float, float]:
    """(fill, cut) in m3: the heights above and below the base, times the covered cell areas."""
    a = window.share * survey.grid.cell_area
    return float(np.sum(a * np.clip(d, 0, None))), float(np.sum(a * np.clip(-d, 0, None)))


def _volume(d: np.ndarray, window: Window, survey: Survey) -> float:
    """The net volume (m3) of heights ``d`` above a base over the window's covered cells."""
    return float(np.sum(window.share * survey.grid.cell_area * d))


def toe_rise(toe: Toe) -> float:
    """How much the toe's plane rises across the toe (m)."""
    a, b, c = toe.plane()
    z = b * toe.x + c * toe.y
    return float(z.max() - z.min())


def toe_warnings(toe: Toe) -> tuple[str, ...]:
    """Warnings when the toe runs over a slope or departs from its plane (another object, a
    neighbour's skirt, uneven ground) by more than :data:`TOE_SIGMAS` cell noises."""
    level = TOE_SIGMAS * toe.noise
    out = []
    rise = toe_rise(toe)
    if rise > level:
        out.append(
            f"toe on a slope: its plane rises {rise:.2f} m across the pile (lowest, average and highest "
            "bases do not follow it)"
        )
    a, b, c = toe.plane()
    off = toe.z - (a + b * toe.x + c * toe.y)
    far = np.abs(off - np.median(off)) > level
    if far.any():
        out.append(
            f"toe runs over something: {toe.weight[far].sum():.1f} m of it stands up to "
            f"{np.max(np.abs(off[far])):.2f} m off the toe's plane (another object, a pile's skirt or uneven ground)"
        )
    if toe.missing > 0:
        out.append(f"{toe.missing:.1f} m of the toe has no survey heights near it (left out of the base)")
    return tuple(out)


def _empty_warning(empty: float) -> tuple[str, ...]:
    """A warning when a pile's area is partly without a measured height (filled from the nearest)."""
    if empty <= EMPTY_WARNING:
        return ()
    return (f"{100 * empty:.0f} % of the pile's area has no measured height (interpolated from the cells around)",)
