"""writers.las (through :func:`soilvolume.inputs.io.write_las`) and writers.gdal (GeoTIFF rasters)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj

from ...core.types import SoilVolumeError
from ...dem.geotiff import Layout, write_geotiff
from ...inputs import io
from . import gdalgrid, geometry
from .view import PointView, StageContext

LAS_OPTS = {
    "filename",
    "compression",
    "a_srs",
    "scale_x",
    "scale_y",
    "scale_z",
    "offset_x",
    "offset_y",
    "offset_z",
    "minor_version",
    "dataformat_id",
    "forward",
}
GDAL_OPTS = {
    "filename",
    "resolution",
    "radius",
    "power",
    "gdaldriver",
    "output_type",
    "data_type",
    "window_size",
    "nodata",
    "dimension",
    "bounds",
    "origin_x",
    "origin_y",
    "width",
    "height",
    "override_srs",
    "default_srs",
    "binmode",
}
_DTYPES = {
    "double": "float64",
    "float64": "float64",
    "float": "float32",
    "float32": "float32",
    "int32": "int32",
    "int16": "int16",
    "uint8": "uint8",
    "uint16": "uint16",
    "uint32": "uint32",
}
_NODATA = {
    "float64": -9999.0,
    "float32": -9999.0,
    "int32": -9999,
    "int16": -9999,
    "uint8": 255,
    "uint16": 9999,
    "uint32": 9999,
}


def _filename(opts: dict, ctx: StageContext) -> Path:
    name = ctx.string(opts, "filename")
    if not name:
        raise ctx.error("option 'filename' is required")
    if "#" in name:
        raise ctx.error("'#' placeholders (one file per view) are not supported")
    return Path(name)


def write_las(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """LAS 1.4 / LAZ by suffix; one scale for X/Y/Z (PDAL's default 0.01), automatic offsets."""
    path = _filename(opts, ctx)
    scales = {ctx.number(opts, f"scale_{a}", 0.01) for a in "xyz"}
    if len(scales) != 1:
        raise ctx.error("different scale_x/scale_y/scale_z are not supported by the embedded executor")
    for a in "xyz":
        off = opts.get(f"offset_{a}", "auto")
        if off != "auto":
            raise ctx.error(f"option 'offset_{a}' other than 'auto' is not supported")
    if str(opts.get("compression", "")).lower() in ("laszip", "lazperf", "true") and path.suffix.lower() != ".laz":
        raise ctx.error("compression needs a .laz filename in the embedded executor")
    wkt = view.srs_wkt
    if ctx.string(opts, "a_srs"):
        wkt = pyproj.CRS.from_user_input(opts["a_srs"]).to_wkt()
    cls = view.arrays.get("Classification")
    try:
        io.write_las(path, view.xyz, wkt, cls, scale=scales.pop())
    except OSError as exc:
        raise ctx.error(f"{path}: cannot write ({exc})") from exc
    return view


def _grid(view: PointView, opts: dict, res: float, ctx: StageContext) -> gdalgrid.Grid:
    keys = [k for k in ("origin_x", "origin_y", "width", "height") if k in opts]
    if keys and len(keys) != 4:
        raise ctx.error("must specify all or none of 'origin_x', 'origin_y', 'width' and 'height'")
    if keys and "bounds" in opts:
        raise ctx.error("specify either 'bounds' or 'origin_x'/'origin_y'/'width'/'height'")
    if keys:
        w, h = ctx.integer(opts, "width"), ctx.integer(opts, "height")
        if w < 1 or h < 1:
            raise ctx.error("'width' and 'height' must be >= 1")
        return gdalgrid.Grid(ctx.number(opts, "origin_x"), ctx.number(opts, "origin_y"), w, h, res)
    if "bounds" in opts:
        try:
            (x0, x1), (y0, y1) = geometry.parse_bounds(opts["bounds"])[:2]
        except (SoilVolumeError, ValueError, KeyError) as exc:
            raise ctx.error(f"bad 'bounds' ({exc})") from exc
        return gdalgrid.grid_from_bounds(x0, y0, x1, y1, res)
    if len(view) == 0:
        raise ctx.error("unable to write GDAL data with no points for output")
    x, y = view.arrays["X"], view.arrays["Y"]
    return gdalgrid.grid_from_bounds(x.min(), y.min(), x.max(), y.max(), res)


def gdal_rasters(view: PointView, opts: dict, ctx: StageContext):
    """(grid, {stat: raster}) as writers.gdal would compute them."""
    res = ctx.positive(opts, "resolution")
    if res is None:
        raise ctx.error("option 'resolution' is required")
    stats: list[str] = []
    for text in ctx.strings(opts, "output_type") or ["all"]:
        for s in (t.strip() for t in text.split(",")):
            if s == "all":
                stats = list(gdalgrid.STATS)
            elif s in gdalgrid.STATS:
                stats.append(s)
            else:
                raise ctx.error(f"invalid output type '{s}'")
    key = view.dim(ctx.string(opts, "dimension", "Z"))
    if key is None:
        raise ctx.error(f"specified dimension '{opts.get('dimension')}' does not exist")
    grid = _grid(view, opts, res, ctx)
    rasters = gdalgrid.compute(
        grid,
        view.arrays["X"],
        view.arrays["Y"],
        view.arrays[key].astype(np.float64),
        stats=stats,
        binmode=ctx.boolean(opts, "binmode", False),
        radius=ctx.positive(opts, "radius"),
        power=ctx.number(opts, "power", 1.0),
        window_size=ctx.integer(opts, "window_size", 0),
    )
    return grid, rasters


def write_gdal(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Bands in PDAL's order (min, max, mean, idw, count, stdev), each named by its statistic."""
    import rasterio
    from rasterio.transform import from_origin

    path = _filename(opts, ctx)
    grid, rasters = gdal_rasters(view, opts, ctx)
    dtype = _DTYPES.get(str(opts.get("data_type", "double")).lower())
    if dtype is None:
        raise ctx.error(f"data_type '{opts.get('data_type')}' is not supported")
    nodata = ctx.number(opts, "nodata", _NODATA[dtype])
    srs = ctx.string(opts, "override_srs") or view.srs_wkt or ctx.string(opts, "default_srs")
    crs = pyproj.CRS.from_user_input(srs).to_wkt() if srs else None
    transform = from_origin(grid.x0, grid.y0 + grid.res * grid.height, grid.res, grid.res)
    driver = ctx.string(opts, "gdaldriver", "GTiff")
    layout = Layout(grid.width, grid.height, transform, crs, dtype, nodata, len(rasters), tuple(rasters), driver=driver)
    try:
        write_geotiff(path, list(rasters.values()), layout)
    except rasterio.errors.RasterioError as exc:
        raise ctx.error(f"{path}: cannot write raster ({exc})") from exc
    return view
