"""The stockpile inventory of one survey: every pile's volume above its base, from the toe
polygons given or from the piles found in the survey (the step a run composes)."""

from __future__ import annotations

from collections.abc import Sequence

from .bases import check_surface
from .find import FindSettings, find_piles
from .measure import measure_pile
from .survey import Survey
from .types import DEFAULT_BASE, Base, Inventory, Pile, PileError, checked_density, checked_polygon, parse_base


def stockpile_inventory(
    survey: Survey,
    piles: Sequence[Pile] | None = None,
    base: Base | str = DEFAULT_BASE,
    density: float | None = None,
    find: FindSettings | None = None,
) -> Inventory:
    """The :class:`Inventory` of ``survey`` (:func:`~.survey.survey_from_points` or
    :func:`~.survey.survey_from_dem`): each of ``piles`` (toe polygons in the survey's local frame)
    or, without them, each pile found in it (:func:`~.find.find_piles` with ``find``), measured
    above ``base`` (a :class:`Base` or its option text; ``surface`` needs a :class:`Base` holding
    the array); ``density`` (t/m3) for the piles without their own. Raises :class:`PileError`
    (one line) for a bad polygon, density or base before anything is measured."""
    checked_density(density)
    base = parse_base(base) if isinstance(base, str) else base
    check_surface(base, survey.heights.shape)
    found = piles is None
    if found:
        piles = find_piles(survey, find)
    elif not piles:
        raise PileError("no pile polygon given")
    for i, pile in enumerate(piles):
        checked_polygon(pile.polygon, pile.name or f"pile {i + 1}")
        checked_density(pile.density, pile.name or f"pile {i + 1}")
    results = tuple(measure_pile(survey, pile, base, i, density) for i, pile in enumerate(piles))
    return Inventory(results, survey.grid.cell, survey.noise(), found)
