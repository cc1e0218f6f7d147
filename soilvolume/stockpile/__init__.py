"""Stockpile inventory from one survey: each pile's volume above its base inside its toe
polygon, with a 95 % interval, cut and fill, tonnage and the toe's warnings; piles found in the
survey when no polygon is given. The step a run composes is :func:`stockpile_inventory` over a
:class:`Survey` (:func:`survey_from_points` or :func:`survey_from_dem`); ``writers`` writes its
outputs and ``reader`` reads the toe polygons of a vector file.
"""

from .find import FindSettings, find_piles
from .inventory import stockpile_inventory
from .survey import Survey, survey_from_dem, survey_from_points
from .types import Base, Inventory, Pile, PileError, PileVolume, parse_base

__all__ = [
    "Base",
    "FindSettings",
    "Inventory",
    "Pile",
    "PileError",
    "PileVolume",
    "Survey",
    "find_piles",
    "parse_base",
    "stockpile_inventory",
    "survey_from_dem",
    "survey_from_points",
]
