"""``contours.gpkg``: GDAL's ``GDALContourGenerateEx`` on the difference (``change``: cut, fill or
none) and both DEMs, one layer each, no line across nodata; through GDAL's Python bindings where
they import, else by :mod:`ctypes` in the GDAL rasterio loaded (:mod:`.gdalcapi`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..core.types import SoilVolumeError
from . import gdalcapi

FILE = "contours.gpkg"
#: layer -> the raster of the run it contours
LAYERS = (("difference", "difference.tif"), ("dem_before", "dem_before.tif"), ("dem_after", "dem_after.tif"))
KIND_SQL = "UPDATE difference SET change = CASE WHEN ELEV < 0 THEN 'cut' WHEN ELEV > 0 THEN 'fill' ELSE 'none' END"


def contour_options(interval: float, nodata: float | None) -> list[str]:
    """``GDALContourGenerateEx``'s options: levels at every multiple of ``interval``."""
    opts = [f"LEVEL_INTERVAL={interval!r}", "LEVEL_BASE=0", "ID_FIELD=0", "ELEV_FIELD=1"]
    return opts + ([f"NODATA={nodata!r}"] if nodata is not None else [])


def write_contours(path: str | Path, folder: Path, interval: float) -> dict:
    """Write ``path`` (a GeoPackage) with a layer of contours per raster of :data:`LAYERS` found in
    ``folder``, every ``interval`` m; returns {"file", "interval_m", "lines": {layer: count}}."""
    if not interval > 0:
        raise SoilVolumeError(f"contour interval: {interval} m is not above 0")
    path = Path(path)
    rasters = [(name, folder / tif) for name, tif in LAYERS if (folder / tif).is_file()]
    backend = _osgeo() or gdalcapi.Gdal()
    counts = backend.contours(str(path), rasters, lambda nodata: contour_options(interval, nodata), KIND_SQL)
    return {"file": path.name, "interval_m": interval, "lines": counts}


def _osgeo():
    """The GDAL Python bindings' backend, or None where they do not import."""
    try:
        from osgeo import gdal, ogr, osr
    except ImportError:
        return None
    return _Osgeo(gdal, ogr, osr)


class _Osgeo:
    """GDALContourGenerateEx through ``osgeo`` (the calls of :class:`gdalcapi.Gdal`)."""

    def __init__(self, gdal, ogr, osr) -> None:
        self.gdal, self.ogr, self.osr = gdal, ogr, osr

    def contours(self, path: str, rasters: list, options_for: Callable, kind_sql: str) -> dict[str, int]:
        gdal = self.gdal
        gdal.ErrorReset()
        out = gdal.GetDriverByName("GPKG").Create(path, 0, 0, 0, gdal.GDT_Unknown)
        if out is None:
            raise SoilVolumeError(f"{path}: {gdal.GetLastErrorMsg() or 'cannot create'}")
        counts = {name: self._layer(out, name, str(tif), options_for) for name, tif in rasters}
        if "difference" in counts:
            out.ExecuteSQL(kind_sql)
        out = None  # closed: written
        return counts

    def _layer(self, out, name: str, tif: str, options_for: Callable) -> int:
        gdal, ogr, osr = self.gdal, self.ogr, self.osr
        src = gdal.Open(tif)
        band, wkt = src.GetRasterBand(1), src.GetProjectionRef()
        layer = out.CreateLayer(name, osr.SpatialReference(wkt=wkt) if wkt else None, ogr.wkbLineString)
        fields = [("ID", ogr.OFTInteger), ("ELEV", ogr.OFTReal)]
        for field, kind in fields + ([("change", ogr.OFTString)] if name == "difference" else []):
            layer.CreateField(ogr.FieldDefn(field, kind))
        out.StartTransaction()
        if gdal.ContourGenerateEx(band, layer, options=options_for(band.GetNoDataValue())) != 0:
            raise SoilVolumeError(f"contours of {tif}: {gdal.GetLastErrorMsg() or 'GDAL failed'}")
        out.CommitTransaction()
        return layer.GetFeatureCount()
