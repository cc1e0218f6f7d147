"""The execution seam: one small protocol, :class:`Backend`, and the typed results that cross it.

A backend decides where a step's point work runs and how its inputs are cut: whole arrays in
this process (:class:`~soilvolume.execution.inmemory.InMemory`) or Dask tasks over tiles of the
grid (:class:`~soilvolume.execution.tiled.Tiled`). It never decides which steps run, in what order,
or how a number is computed: the steps hand it their functions (the planes' fit, the volume step)
and it returns the merged typed result."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..core.types import GridSpec

#: the volume step as the backend runs it: (after DEM, before DEM, d_i, grid) -> Volumes
VolumeFn = Callable[[Any, Any, np.ndarray, GridSpec], Any]


@dataclass(frozen=True)
class Gridded:
    """(after, before) ``EpochDEM`` s on the grid; ``correction_grid``/``_dems``: where the planes and
    the correction are found (the grid, or a tiled run's overview); ``beside``: the planes' fit."""

    grid: GridSpec
    dems: tuple
    correction_grid: GridSpec
    correction_dems: tuple
    beside: Future


class Backend(Protocol):
    """Where a product's steps run (see module)."""

    reading_note: str  # after the reading step's message: what the reading does on this backend
    raster_note: str  # after the writing step's message: the kind of raster written

    def session(self, ctx) -> AbstractContextManager[Backend]:
        """The backend's resources (threads, a cluster, a tile store) for one run."""

    def read(self, ctx) -> Any:
        """The pair read into one working frame (``inputs.prepare.Prepared``)."""

    def dense(self, prep) -> tuple | None:
        """The full-resolution (after, before) points the registration may refine on, or None."""

    def grid(self, ctx, prep, reg, grid: GridSpec, beside: Callable) -> Gridded:
        """Both epochs' heights on ``grid``; ``beside(grid, before DEM)`` run meanwhile."""

    def volume(self, ctx, step: VolumeFn, gridded: Gridded, planes: tuple, moved) -> Any:
        """``step`` over the grid (or by tiles given the overview's); ``planes``: (before, after, d_i
        on the correction's grid); ``moved``: the registration's other pose (a 4x4 move, or None)."""

    def write(self, ctx, layers: list, vols, grid: GridSpec, z0: float) -> None:
        """The rasters ``layers`` (file name, array name, description) of ``vols`` on ``grid``."""

    def keep_cloud(self, prep, reg, path: Path) -> None:
        """Write the after cloud moved by ``reg`` to ``path`` (done by :meth:`write` at the latest)."""

    def engine(self) -> dict | None:
        """report.json's ``engine``: where the work ran and what it cost (None in-process)."""


def done(value) -> Future:
    """A future already holding ``value``."""
    future: Future = Future()
    future.set_result(value)
    return future
