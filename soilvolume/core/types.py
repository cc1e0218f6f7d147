"""Plain data types shared by the engine's steps."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .wording import cli


class SoilVolumeError(Exception):
    """A problem a user can act on, naming the file; its option markers (:func:`.wording.opt`) worded
    as flags by ``str()``, kept by :attr:`keyed`."""

    @property
    def keyed(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __str__(self) -> str:
        return cli(self.keyed)


def short_error(exc: BaseException, limit: int = 160) -> str:
    """A library exception's message on one line, WKT as '<WKT>', at most ``limit`` characters (else its type)."""
    text = re.sub(r"[A-Z_]{4,}\[.*\]", "<WKT>", " ".join(str(exc).split())) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Cloud:
    """A point cloud in local coordinates: absolute = ``xyz + origin`` (metres, in ``crs``), ``xyz`` float64."""

    xyz: np.ndarray
    origin: np.ndarray
    crs_wkt: str | None = None
    path: str = ""
    classification: np.ndarray | None = None
    nonsoil: Any = None  # soil.points.NonSoil: the points read beside these that are not soil

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


@dataclass(frozen=True)
class GridSpec:
    """A north-up grid: ``xmin``/``ymax`` the absolute top-left corner on multiples of ``cell``, ``origin``
    the local origin of the engine's arrays."""

    xmin: float
    ymax: float
    cell: float
    rows: int
    cols: int
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    crs_wkt: str | None = None
    xy_unit: float = 1.0  # metres per horizontal CRS unit (rasters are written in CRS units)

    @property
    def transform(self):
        """The rasterio/GDAL affine transform in the CRS's own units."""
        from affine import Affine

        u = self.xy_unit
        return Affine(self.cell / u, 0.0, self.xmin / u, 0.0, -self.cell / u, self.ymax / u)

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid's (lo, hi) corners, absolute x/y (metres)."""
        lo = np.array([self.xmin, self.ymax - self.rows * self.cell])
        return lo, np.array([self.xmin + self.cols * self.cell, self.ymax])

    @property
    def cell_area(self) -> float:
        return self.cell * self.cell

    def centers_local(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates (local frame) as two (rows, cols) arrays."""
        xs = self.xmin + (np.arange(self.cols) + 0.5) * self.cell - self.origin[0]
        ys = self.ymax - (np.arange(self.rows) + 0.5) * self.cell - self.origin[1]
        return np.meshgrid(xs, ys)

    def window(self, r0: int, r1: int, c0: int, c1: int) -> GridSpec:
        """The sub-grid of rows r0..r1 and columns c0..c1 (same cells, same origin)."""
        x0, y0 = self.xmin + c0 * self.cell, self.ymax - r0 * self.cell
        return replace(self, xmin=x0, ymax=y0, rows=r1 - r0, cols=c1 - c0)

    def index(self, xy_local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) for local x/y points."""
        col = np.floor((xy_local[:, 0] + self.origin[0] - self.xmin) / self.cell).astype(np.int64)
        row = np.floor((self.ymax - xy_local[:, 1] - self.origin[1]) / self.cell).astype(np.int64)
        inside = (row >= 0) & (row < self.rows) & (col >= 0) & (col < self.cols)
        return row, col, inside


@dataclass(frozen=True)
class StageQuality:
    """Quality of one registration stage, as Open3D reports it."""

    method: str
    fitness: float
    rmse: float
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    accepted: bool = True
    seconds: float = 0.0
    note: str = ""
    alternative: np.ndarray | None = None  # a nearly as good pose (its spread from ``transform`` is uncertainty)
    beyond_prior: int = 0  # poses that fitted but lay beyond the georeferencing prior, rejected
    poses: tuple = ()  # every pose the fine stage refined to (4x4s, those beyond the prior too): its own spread


TILE_SUFFIXES = (".vpc", ".copc.laz")


@dataclass(frozen=True)
class Epoch:
    """One survey of a run, in time order: its source (``cloud``: a point cloud file, maybe through a PDAL
    pipeline; ``tiles``: a VPC, a COPC file or a folder; ``surface``: a DEM GeoTIFF or a LandXML TIN), the CRS
    given for a file without one, its ISO date and its source (``"LAS header"``, ``"given"``), how far its
    georeferencing is trusted."""

    path: Path
    source: str = "cloud"
    pipeline: Path | None = None
    crs: str | None = None
    date: str | None = None
    date_source: str | None = None
    georeferencing: str = "auto"

    @property
    def name(self) -> str:
        return Path(self.path).name

    @property
    def is_surface(self) -> bool:
        return self.source == "surface"


def survey(path, pipeline=None, **fields) -> Epoch:
    """A survey epoch: ``tiles`` for a VPC, a COPC file or a folder, else ``cloud``."""
    path = Path(path)
    tiled = path.is_dir() or path.name.lower().endswith(TILE_SUFFIXES)
    source = "tiles" if tiled and pipeline is None else "cloud"
    return Epoch(path, source, None if pipeline is None else Path(pipeline), **fields)
