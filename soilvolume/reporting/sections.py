"""``--sections``: the written DEMs and difference sampled every half cell along each line (brought
into the run's CRS as the zones are), as ``sections.csv`` (a cell without a height: an empty value)
and one picture per line, ``sections/<name>.svg`` (:mod:`.sectionsvg`)."""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.types import GridSpec, SoilVolumeError
from ..inputs.io import atomic_path
from ..volumes.polygons import read_lines, to_grid_crs
from .sectionsvg import profile_svg

FILE = "sections.csv"
FOLDER = "sections"
COLUMNS = ("line_id", "name", "chainage_m", "x", "y", "before", "after", "difference")
RASTERS = ("dem_before.tif", "dem_after.tif", "difference.tif")


@dataclass(frozen=True)
class Profile:
    """One line's samples: chainage (m), x, y (the CRS's units), before, after, difference (m)."""

    id: int
    name: str
    chainage: np.ndarray
    xy: np.ndarray
    heights: np.ndarray  # (n, 3): before, after, difference; NaN where a raster has no height


def stations(line, step: float) -> tuple[np.ndarray, np.ndarray]:
    """(chainage, xy) every ``step`` along ``line`` (CRS units) and at each part's end; a
    multi-line's parts follow each other, its chainage running on."""
    import shapely  # heavy: only a run with --sections loads it

    chain, points, start = [], [], 0.0
    for part in shapely.get_parts(line):
        along = np.append(np.arange(0.0, part.length, step), part.length)
        points.append(shapely.get_coordinates(shapely.line_interpolate_point(part, along)))
        chain.append(start + along)
        start += part.length
    return np.concatenate(chain), np.concatenate(points)


def sample(folder: Path, xy: np.ndarray) -> np.ndarray:
    """(n, 3) heights of :data:`RASTERS` in ``folder`` at ``xy`` (nearest cell; NaN off the grid
    or on nodata)."""
    import rasterio  # heavy: only a run with --sections loads it here
    from rasterio.transform import rowcol
    from rasterio.windows import Window

    out = np.full((len(xy), len(RASTERS)), np.nan)
    for k, name in enumerate(RASTERS):
        with rasterio.open(folder / name) as ds:
            rows, cols = (np.asarray(v) for v in rowcol(ds.transform, xy[:, 0], xy[:, 1]))
            inside = (rows >= 0) & (rows < ds.height) & (cols >= 0) & (cols < ds.width)
            if not inside.any():
                continue
            r0, c0 = rows[inside].min(), cols[inside].min()  # the window the line crosses, read alone
            window = Window(c0, r0, cols[inside].max() - c0 + 1, rows[inside].max() - r0 + 1)
            band = ds.read(1, window=window, masked=True).astype(float)
            out[inside, k] = np.ma.filled(band[rows[inside] - r0, cols[inside] - c0], np.nan)
    return out


def profiles(path: str | Path, folder: Path, grid: GridSpec) -> list[Profile]:
    """Every line of ``path`` sampled on the rasters in ``folder``; an error naming the file when
    no line crosses a cell with a height (outside the survey, or in another CRS)."""
    lines, wkt = read_lines(path)
    lines = to_grid_crs(lines, wkt, grid, path)
    step = grid.cell / 2 / grid.xy_unit
    out = []
    for line in lines:
        chain, xy = stations(line.geometry, step)
        out.append(Profile(line.id, line.name, chain * grid.xy_unit, xy, sample(folder, xy)))
    if not any(np.isfinite(p.heights[:, 1]).any() for p in out):
        hint = "" if wkt else " (the file has no CRS: is it in the survey's?)"
        raise SoilVolumeError(f"{path}: no section line crosses the surveyed grid{hint}")
    return out


def write_sections(path: str | Path, folder: Path, grid: GridSpec, before: str = "before") -> dict:
    """``sections.csv`` and ``sections/<name>.svg`` in ``folder`` (the staged rasters') of the lines of
    ``path``; ``before``: the before heights' name (``design`` against a surface). report.json's ``sections``."""
    found = profiles(path, folder, grid)
    with atomic_path(folder / FILE) as part, open(part, "w", newline="", encoding="utf-8") as f:
        out = csv.writer(f)
        out.writerow([before if c == "before" else c for c in COLUMNS])
        for p in found:
            for c, (x, y), h in zip(p.chainage, p.xy, p.heights, strict=True):
                out.writerow([p.id, p.name, round(float(c), 3), x, y, *("" if np.isnan(v) else v for v in h)])
    pictures = write_pictures(found, folder / FOLDER, before)
    return {"file": FILE, "lines": len(found), "pictures": pictures}


def write_pictures(found: list[Profile], folder: Path, before: str) -> list[str]:
    """One SVG per line with heights in ``folder``, named after the line (made unique)."""
    folder.mkdir()
    names: list[str] = []
    for p in found:
        if not np.isfinite(p.heights[:, :2]).any():
            continue
        stem = re.sub(r"[^\w.-]+", "_", p.name).strip("._") or f"line_{p.id}"
        name = f"{stem}.svg" if f"{stem}.svg" not in names else f"{stem}_{p.id}.svg"
        svg = profile_svg(p.name, p.chainage, p.heights[:, 0], p.heights[:, 1], before)
        (folder / name).write_text(svg, encoding="utf-8")
        names.append(name)
    return [f"{FOLDER}/{n}" for n in names]
