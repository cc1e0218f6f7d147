"""The point buffer passed between embedded stages, and option parsing shared by the stages."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.types import SoilVolumeError

#: dtypes of the dimensions the embedded stages create; others are kept as read.
DIM_TYPES: dict[str, type] = {"Classification": np.uint8}


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
        """The array of a dimension, created as zeros when missing (PDAL's registerDim)."""
        key = self.dim(name)
        if key is None:
            key = name
            self.arrays[key] = np.zeros(len(self), dtype=DIM_TYPES.get(name, np.float64))
        return self.arrays[key]


class StageContext:
    """What a stage needs to report errors: the pipeline's name and the stage's type."""

    def __init__(self, source: str, stage: str) -> None:
        self.source = source
        self.stage = stage

    def error(self, problem: str) -> SoilVolumeError:
        return SoilVolumeError(f"pipeline {self.source}: {self.stage}: {problem}")

    # option accessors: PDAL accepts numbers as JSON values or as strings
    def number(self, opts: dict, name: str, default: float | None = None) -> float | None:
        if name not in opts:
            return default
        value = opts[name]
        try:
            if isinstance(value, bool):
                raise ValueError
            out = float(value)
        except (TypeError, ValueError):
            raise self.error(f"option '{name}' must be a number, got {value!r}") from None
        if not math.isfinite(out):
            raise self.error(f"option '{name}' must be finite, got {value!r}")
        return out

    def positive(self, opts: dict, name: str, default: float | None = None) -> float | None:
        out = self.number(opts, name, default)
        if out is not None and out <= 0:
            raise self.error(f"option '{name}' must be > 0, got {opts.get(name)!r}")
        return out

    def string(self, opts: dict, name: str, default: str | None = None) -> str | None:
        value = opts.get(name, default)
        if value is not None and not isinstance(value, str):
            raise self.error(f"option '{name}' must be a string, got {value!r}")
        return value

    def strings(self, opts: dict, name: str) -> list[str]:
        """A multi-valued option: a string or a list of strings."""
        value = opts.get(name)
        if value is None:
            return []
        items = value if isinstance(value, list) else [value]
        for item in items:
            if not isinstance(item, str):
                raise self.error(f"option '{name}' must be a string or a list of strings")
        return list(items)
