"""The volume step's frozen results: :class:`Volumes` in typed parts, and a tile's :class:`Given`."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..dem.grid import EpochDEM

Epochs = tuple[EpochDEM, EpochDEM]  # (after, before)


@dataclass(frozen=True)
class Grids:
    """The volume step's grids on the shared grid (m; masks bool)."""

    dem_a: np.ndarray  # H_after the difference is taken from: heights at the cell centres (local)
    dem_b: np.ndarray  # H_before, the same
    raw: np.ndarray  # H_after - H_before, NaN where either epoch is empty
    filled: np.ndarray  # the same with weak cells and enclosed holes refilled
    filled_mask: np.ndarray  # the refilled cells
    offset: np.ndarray  # the correction subtracted (d_i and/or the stable-ground surface)
    diff: np.ndarray  # the corrected difference: filled - offset
    stable: np.ndarray  # the stable cells of the error model
    change_mask: np.ndarray  # the areas of significant change (moved objects left out)
    cut_mask: np.ndarray  # the cut areas of change_mask, after the exclusions (the rest of it is fill)
    classes: np.ndarray  # excluded.tif: the class of each cell (volumes/nonsoil.CLASS_CODES)
    dem_out_a: np.ndarray  # dem_after.tif: dem_a, the refilled heights on filled_mask (local)
    dem_out_b: np.ndarray  # dem_before.tif: the same; dem_out_a - dem_out_b - offset = diff


@dataclass(frozen=True)
class Budgets:
    """The budgets (m3, as report.json holds them: net, cut, fill, cells, area_m2)."""

    compensated: dict  # the headline: fill and cut over the change areas
    all_cells: dict  # every compared cell
    uncompensated: dict  # the refilled difference without correction
    paper_plane: dict  # the paper's H_after - H_before - d_i over every compared cell
    thresholded: dict  # cells above the LoD only
    holes: dict  # refilled area and volume
    zones: list = field(default_factory=list)  # per-polygon budgets (--zones)


@dataclass(frozen=True)
class Cells:
    """What was compared: empty cells of the grid and the after footprint's coverage."""

    empty_cells: int
    empty_before: int
    empty_after: int
    coverage: dict  # the after footprint's cells compared (volumes/coverage)


@dataclass(frozen=True)
class Volumes:
    """The volume step's parts, ``params``, ``uncertainty``, ``excluded`` and ``blind``; parts' fields read on the
    whole."""

    grids: Grids
    budgets: Budgets
    cells: Cells
    params: dict
    uncertainty: dict
    excluded: dict = field(default_factory=dict)
    blind: dict = field(default_factory=dict)

    def with_(self, **changes) -> Volumes:
        """A copy with ``changes``, each a field of the whole or of one of its parts."""
        parts = {p: {k: v for k, v in changes.items() if _PART.get(k) == p} for p in set(_PART.values())}
        own = {k: v for k, v in changes.items() if k not in _PART}
        return replace(self, **own, **{p: replace(getattr(self, p), **kw) for p, kw in parts.items() if kw})


def _from(part: str, name: str) -> property:
    """The read-only attribute ``name`` of the whole, read from its ``part``."""
    return property(lambda self: getattr(getattr(self, part), name), doc=f"``{part}.{name}``")


_PART = {f.name: part for part, cls in (("grids", Grids), ("budgets", Budgets), ("cells", Cells)) for f in fields(cls)}
for _name, _part in _PART.items():  # every part's field an attribute of the whole, as other packages read them
    setattr(Volumes, _name, _from(_part, _name))
Volumes.change_areas = _from("budgets", "compensated")  # the headline's other name in report.json


@dataclass(frozen=True)
class Given:
    """What a tile takes from the whole grid's overview: correction, stable ground, median counts, the core it
    counts."""

    offset: np.ndarray  # the correction surface on the window (m)
    stable: np.ndarray  # stable ground on the window
    params: dict  # the correction's parameters
    median_counts: tuple[float, float]  # (after, before)
    core: tuple[slice, slice]
