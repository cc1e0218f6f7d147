"""The typed record of a run, what :mod:`soilvolume.reporting.report` turns into report.json
(the one place that does): the georeferencing decision, each step's typed result (budgets and
uncertainty terms are the volume step's ``Volumes``) and what the quality verdict judges."""

from __future__ import annotations

from dataclasses import asdict, dataclass
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

    def as_dict(self) -> dict[str, str]:
        return asdict(self)


@dataclass(frozen=True)
class QualityInputs:
    """What ``volumes/quality.assess`` judges beside report.json's figures: the cells of stable
    ground and of change, the correction surface and the difference (on the grid the correction
    was found on), its cell area, and the georeferencing prior (shift m, rotation and tilt deg)."""

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
