"""A height raster (a design surface, a DEM) read in metres, the one way every command reads one: the
band's scale and offset applied, its nodata and GDAL mask masked, its unit honoured (a vertical CRS's
axis, else the band's unit; contradicting: refused), over a window only (more cells than
:func:`max_cells` refused in one line naming the remedy).

Values no height can take, beyond :data:`NOT_A_HEIGHT_M` (an undeclared 1e30 or -3.4e38 fill) or an
undeclared :data:`FILLS` value :data:`FAR_BELOW_M` below the median, are masked and said
(:attr:`Heights.masked`): refusing would stop a survey over a common export quirk, taking them as
heights would give millions of m³."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from ..core.outputs import check_input_file
from ..core.types import SoilVolumeError
from .crs import horizontal, z_unit

#: metres per height unit, by the band's unit name (lower case; none: metres)
UNITS = dict.fromkeys(("", "m", "metre", "meter", "metres", "meters"), 1.0)
UNITS |= dict.fromkeys(("ft", "foot", "feet"), 0.3048)
UNITS |= dict.fromkeys(("us survey foot", "us-ft", "ftus", "us_survey_foot"), 0.3048006096)
UNITS |= dict.fromkeys(("cm", "centimetre", "centimeter", "centimetres", "centimeters"), 0.01)
UNITS |= dict.fromkeys(("mm", "millimetre", "millimeter", "millimetres", "millimeters"), 0.001)
NOT_A_HEIGHT_M = 1e5  # m from the datum: no height on Earth is this far (Everest 8.8 km, the deepest sea 11 km)
FILLS = (-9999.0, -99999.0, -32767.0, -32768.0)  # stored values programs leave for "no height"
FAR_BELOW_M = 1000.0  # an undeclared fill this far below the median height is no height
MAX_CELLS = 400_000_000  # cells read at once at most, as a run's grid (dem/grid.make_grid); see max_cells
BLOCK_CELLS = 1 << 20  # cells converted at a time (the stored values' copy stays this small)


@dataclass(frozen=True)
class HeightRaster:
    """A single-band height raster opened and checked; no pixel read yet."""

    path: str
    width: int
    height: int
    transform: Any  # affine.Affine of the whole raster
    crs: pyproj.CRS | None  # its own CRS (None when it has none)
    unit: str  # the band's declared unit, lower case ("" when none)
    scale: float
    offset: float
    nodata: float | None
    dtype: str

    def describe(self) -> dict:
        """What the raster declares (report.json)."""
        nodata = None if self.nodata is None else _number(self.nodata)
        return {"scale": self.scale, "offset": self.offset, "nodata": nodata, "dtype": self.dtype}


@dataclass(frozen=True)
class Heights:
    """Heights in metres (NaN where none) over a window of a raster, with the window's transform."""

    z: np.ndarray  # (rows, cols) float64
    transform: Any  # affine.Affine of the window
    window: tuple[int, int, int, int]  # (col_off, row_off, cols, rows) within the raster
    masked: list[dict] = field(default_factory=list)  # cells taken as nodata: values, cells, why


def _number(value: float) -> float | str:
    """``value`` for JSON: a finite float, else its name ("nan", "inf", "-inf")."""
    return float(value) if math.isfinite(value) else str(float(value))


def masked_notes(path: str, masked: list[dict] | tuple[dict, ...]) -> list[str]:
    """One line per kind of value taken as nodata (:attr:`Heights.masked`), for the log."""
    return [
        f"{Path(path).name}: {m['cells']:,} cells hold {', '.join(f'{float(v):g}' for v in m['values'])} ({m['why']}): "
        "taken as nodata"
        for m in masked
    ]


def open_heights(path: Path) -> HeightRaster:
    """Open ``path`` and check it is a single-band raster; read its declarations, not its pixels."""
    import rasterio

    check_input_file(path)
    try:
        with rasterio.open(path) as ds:
            if ds.count != 1:
                raise SoilVolumeError(f"{path}: the raster must be a single-band DEM; this raster has {ds.count} bands")
            crs = None if ds.crs is None else pyproj.CRS.from_user_input(ds.crs.to_wkt())
            scale, offset = float(ds.scales[0]), float(ds.offsets[0])
            unit, nodata = (ds.units[0] or "").strip().lower(), ds.nodata
            raster = HeightRaster(
                str(path), ds.width, ds.height, ds.transform, crs, unit, scale, offset, nodata, ds.dtypes[0]
            )
    except rasterio.errors.RasterioError as exc:
        raise SoilVolumeError(f"{path}: not a readable raster ({' '.join(str(exc).split())[:200]})") from exc
    if not (math.isfinite(scale) and math.isfinite(offset) and scale != 0):
        raise SoilVolumeError(f"{path}: the band's scale {scale:g} and offset {offset:g} do not give heights")
    return raster


def metres_per_unit(crs: pyproj.CRS, unit: str, path: str) -> tuple[float, str]:
    """(metres per stored height unit, its source in words): a vertical CRS's axis, else the band's
    unit (none: metres); a band unit contradicting the vertical CRS is refused."""
    band = UNITS.get(unit)
    if crs.is_compound or len(crs.axis_info) == 3:
        factor = z_unit(crs)
        if unit and band is not None and not math.isclose(band, factor, rel_tol=1e-6):
            raise SoilVolumeError(
                f"{path}: the band's unit ({unit}) contradicts its vertical CRS ({factor:g} m per unit); "
                "correct the band's unit (gdal_edit.py -units) or the CRS"
            )
        return factor, f"the vertical CRS ({factor:g} m per unit)"
    if band is None:
        raise SoilVolumeError(f"{path}: heights in '{unit}' are not understood (expected metres, cm, mm or feet)")
    return band, "metres" if not unit else f"the band's unit ({unit})"


def window_over(
    raster: HeightRaster, crs: pyproj.CRS, lo: np.ndarray, hi: np.ndarray, box_crs: pyproj.CRS, pad: int = 2
) -> tuple[int, int, int, int] | None:
    """The window (col_off, row_off, cols, rows) of ``raster`` (in ``crs``) covering the box lo..hi (in
    ``box_crs``) and ``pad`` pixels more; None when the box misses the raster."""
    src, dst = horizontal(box_crs), horizontal(crs)
    x0, y0, x1, y1 = float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
    if not src.equals(dst):
        tr = pyproj.Transformer.from_crs(src, dst, always_xy=True)
        x0, y0, x1, y1 = tr.transform_bounds(x0, y0, x1, y1, densify_pts=21, errcheck=False)
    if not all(math.isfinite(v) for v in (x0, y0, x1, y1)):
        return None
    inv = ~raster.transform
    cols, rows = zip(*(inv @ (x, y) for x in (x0, x1) for y in (y0, y1)), strict=True)
    c0, r0 = max(math.floor(min(cols)) - pad, 0), max(math.floor(min(rows)) - pad, 0)
    c1, r1 = min(math.ceil(max(cols)) + pad, raster.width), min(math.ceil(max(rows)) + pad, raster.height)
    return None if c1 <= c0 or r1 <= r0 else (c0, r0, c1 - c0, r1 - r0)


def read_heights(raster: HeightRaster, factor: float, window: tuple[int, int, int, int] | None = None) -> Heights:
    """The heights (m) of ``window`` (the whole raster when None), :data:`BLOCK_CELLS` at a time:
    stored value x scale + offset, x ``factor`` (metres per unit); nodata and values no height can take NaN."""
    import rasterio
    from affine import Affine
    from rasterio.windows import Window

    c0, r0, cols, rows = window or (0, 0, raster.width, raster.height)
    if cols * rows > max_cells():
        where = "in the raster" if window is None else "over the site"
        raise SoilVolumeError(
            f"{raster.path}: {rows:,} x {cols:,} cells {where} are too many to read "
            f"({max_cells():,} at most){_remedy(raster, cols * rows, window is None)}"
        )
    step = max(1, BLOCK_CELLS // max(cols, 1))
    try:
        z = np.empty((rows, cols), np.float64)
        with rasterio.open(raster.path) as ds:
            for top in range(0, rows, step):
                n = min(step, rows - top)
                block = ds.read(1, window=Window(c0, r0 + top, cols, n), masked=True)
                values = (block.data.astype(np.float64) * raster.scale + raster.offset) * factor
                values[np.ma.getmaskarray(block)] = np.nan
                z[top : top + n] = values
        masked = _mask_absurd(z, raster, factor)
    except rasterio.errors.RasterioError as exc:
        raise SoilVolumeError(f"{raster.path}: its cells cannot be read ({' '.join(str(exc).split())[:200]})") from exc
    except MemoryError as exc:
        remedy = _remedy(raster, rows * cols, window is None)
        raise SoilVolumeError(f"{raster.path}: out of memory reading {rows:,} x {cols:,} cells{remedy}") from exc
    return Heights(z, raster.transform @ Affine.translation(c0, r0), (c0, r0, cols, rows), masked)


def _mask_absurd(z: np.ndarray, raster: HeightRaster, factor: float) -> list[dict]:
    """Set to NaN (in place) the values no height can take (see module); what was masked."""
    masked = []
    absurd = (z > NOT_A_HEIGHT_M) | (z < -NOT_A_HEIGHT_M)  # infinities too; NaN is nodata already
    if absurd.any():
        values = [_number(v) for v in np.unique(z[absurd])[:3]]
        masked.append({"values": values, "cells": int(absurd.sum()), "why": "no height on Earth"})
        z[absurd] = np.nan
    if raster.nodata is not None:
        return masked
    fills = [(np.float64(f) * raster.scale + raster.offset) * factor for f in FILLS]
    hits = [(value, hit) for value in fills if (hit := z == value).any()]
    if not hits:
        return masked
    others = z[~np.logical_or.reduce([hit for _, hit in hits]) & ~np.isnan(z)]
    floor = float(np.median(others)) - FAR_BELOW_M if others.size else np.inf
    for value, hit in hits:
        if value < floor:
            z[hit] = np.nan
            why = f"a nodata fill the raster does not declare, {FAR_BELOW_M:g} m and more below its other heights"
            masked.append({"values": [float(value)], "cells": int(hit.sum()), "why": why})
    return masked


def max_cells() -> int:
    """Cells read at once at most: a quarter of the memory in float64, within 2^26..:data:`MAX_CELLS`."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX
        total = 8 << 30
    return int(min(MAX_CELLS, max(1 << 26, total // 32)))


def _remedy(raster: HeightRaster, cells: int, whole: bool) -> str:
    """How to make the raster small enough: coarser cells (gdalwarp -tr), or cropped if read whole."""
    pixel = math.hypot(raster.transform.a, raster.transform.d)
    coarser = pixel * math.sqrt(cells / max_cells()) * 1.05
    shown = f"{coarser:.2g}" if coarser < 1 else f"{math.ceil(coarser):d}"
    name = Path(raster.path).name
    crop = " or crop it to the site (gdalwarp -te xmin ymin xmax ymax)" if whole else ""
    return f"; resample it to coarser cells (e.g. gdalwarp -tr {shown} {shown} -r bilinear {name} coarser.tif){crop}"
