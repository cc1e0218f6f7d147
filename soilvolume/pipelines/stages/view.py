"""The point buffer passed between embedded stages, and option parsing shared by the stages."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyproj

from ...core.types import SoilVolumeError


@dataclass
class PointView:
    """Points as named dimension arrays (PDAL's names: X, Y, Z, Classification...) plus the SRS."""

    arrays: dict[str, np.ndarray]
    srs_wkt: str | None = None

    def __len__(self) -> int:
        return int(self.arrays["X"].shape[0])

    @property
    def xyz(self) -> np.ndarray:
        return np.column_stack([self.arrays["X"], self.arrays["Y"], self.arrays["Z"]])

    def take(self, sel: np.ndarray) -> PointView:
        """A new view with the points selected by a boolean mask or an index array."""
        return PointView({k: v[sel] for k, v in self.arrays.items()}, self.srs_wkt)

    def dim(self, name: str) -> str | None:
        """The stored spelling of a dimension name (PDAL names are case-insensitive)."""
        low = name.lower()
        return next((key for key in self.arrays if key.lower() == low), None)

    def ensure(self, name: str) -> np.ndarray:
        """The array of a dimension, created as zeros when missing (PDAL's registerDim; Classification
        uint8, others float64)."""
        key = self.dim(name)
        if key is None:
            key = name
            self.arrays[key] = np.zeros(len(self), np.uint8 if name == "Classification" else np.float64)
        return self.arrays[key]


class StageContext:
    """A stage's errors (naming the pipeline and the stage) and its options, their types checked
    by :func:`soilvolume.pipelines.load.normalise` already (numbers may be JSON strings)."""

    def __init__(self, source: str, stage: str) -> None:
        self.source = source
        self.stage = stage

    def error(self, problem: str) -> SoilVolumeError:
        return SoilVolumeError(f"pipeline {self.source}: {self.stage}: {problem}")

    def number(self, opts: dict, name: str, default: float, positive: bool = False) -> float:
        """A finite number (> 0 with ``positive``), ``default`` when not given."""
        out = float(opts.get(name, default))
        if not math.isfinite(out) or (positive and out <= 0):
            raise self.error(f"option '{name}' must be {'> 0' if positive else 'finite'}, got {opts.get(name)!r}")
        return out

    def strings(self, opts: dict, name: str) -> list[str]:
        """A multi-valued option: a string or a list of strings."""
        items = opts.get(name, [])
        items = items if isinstance(items, list) else [items]
        if not all(isinstance(item, str) for item in items):
            raise self.error(f"option '{name}' must be a string or a list of strings")
        return items

    def crs(self, text: str, what: str) -> pyproj.CRS:
        """``text`` (the SRS ``what`` names) as a CRS, or the error saying it is not one."""
        try:
            return pyproj.CRS.from_user_input(text)
        except pyproj.exceptions.CRSError as exc:
            raise self.error(f"{what}cannot understand SRS '{text[:80]}' ({exc})") from exc
