"""Volumes in typed parts: every part's field reads on the whole, and with_ replaces fields of
the whole or of a part."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from soilvolume.volumes.results import Budgets, Cells, Grids, Volumes


def _volumes() -> Volumes:
    grids = Grids(**{f.name: np.full((2, 2), float(i)) for i, f in enumerate(fields(Grids))})
    budget = {"net": 1.0, "cut": 0.0, "fill": 1.0, "cells": 1, "area_m2": 1.0}
    budgets = Budgets(*(dict(budget) for _ in range(6)), zones=[{"id": 1}])
    cells = Cells(1, 2, 3, {"after_cells": 4})
    return Volumes(grids, budgets, cells, {"method": "surface"}, {"net": 0.5})


def test_every_part_reads_on_the_whole():
    vols = _volumes()
    for part in ("grids", "budgets", "cells"):
        for f in fields(getattr(vols, part)):
            assert getattr(vols, f.name) is getattr(getattr(vols, part), f.name), f.name
    assert vols.change_areas is vols.compensated  # report.json's other name for the headline
    with pytest.raises(AttributeError):
        vols.nonexistent  # noqa: B018


def test_with_replaces_fields_of_the_whole_and_of_its_parts():
    vols = _volumes()
    new = vols.with_(uncertainty={"net": 2.0}, compensated={"net": 3.0}, empty_cells=9, diff=np.zeros((2, 2)))
    assert new.uncertainty == {"net": 2.0} and new.compensated == {"net": 3.0} and new.empty_cells == 9
    assert not new.diff.any() and new.offset is vols.offset and new.all_cells is vols.all_cells
    assert vols.empty_cells == 1 and vols.compensated["net"] == 1.0  # frozen: the original unchanged
    with pytest.raises(AttributeError):
        vols.diff = np.ones((2, 2))
