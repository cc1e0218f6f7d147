"""The typed record of a run that :mod:`soilvolume.reporting.report` (only) turns into report.json."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .types import GridSpec


@dataclass(frozen=True)
class Georeferencing:
    """How far the surveys' georeferencing was trusted (``registration/georef``: declared, confirm)."""

    requested: str  # --georeferencing: auto, gps or precise
    used: str  # gps (registered within the prior) or precise (coordinates used as they are)
    reason: str
    # auto with a declared vertical datum: what the registration said of the coordinates (outcome
    # confirmed / refuted / inconclusive, the pose's move, the tolerances; registration/georef)
    check: dict | None = None


@dataclass(frozen=True)
class QualityInputs:
    """What ``volumes/quality.assess`` judges beside report.json: stable and change cells, correction and
    difference (on the correction's grid), its cell area, the georeferencing prior (m, deg)."""

    stable: np.ndarray
    change: np.ndarray
    offset: np.ndarray
    diff: np.ndarray
    cell_area: float
    prior: dict[str, float]


@dataclass(frozen=True)
class RunRecord:
    """One estimate: its typed results, in the order the steps made them."""

    prep: Any  # inputs.prepare.Prepared: the epochs in the working frame, the inputs' description
    reg: Any  # registration.register.Registration (its Georeferencing decision in it)
    grid: GridSpec
    planes: tuple  # (before, after) compensation.planes.Plane of the paper
    vols: Any  # volumes.compute.Volumes: grids, budgets, uncertainty terms, zones
    options: Any  # options.Options the run used (precise georeferencing: correction none)
    quality: QualityInputs
    engine: dict | None = None  # the tiled executor's figures (tiles, scheduler, task costs)
