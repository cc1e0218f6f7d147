"""GDAL's contour algorithm by :mod:`ctypes` in the GDAL library rasterio loaded (its wheel's, else a
system one): a pip-installed engine has no GDAL bindings, and rasterio exposes no contouring."""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from pathlib import Path

from ..core.types import SoilVolumeError

CE_FAILURE = 3
GA_READONLY, GDT_UNKNOWN, WKB_LINESTRING, OFT_INTEGER, OFT_REAL, OFT_STRING = 0, 0, 2, 0, 2, 4
P = ctypes.c_void_p
SIGNATURES = {  # name -> (restype, argtypes)
    "GDALAllRegister": (None, []),
    "GDALOpen": (P, [ctypes.c_char_p, ctypes.c_int]),
    "GDALClose": (None, [P]),  # CPLErr since GDAL 3.7: the last error tells
    "GDALGetRasterBand": (P, [P, ctypes.c_int]),
    "GDALGetRasterNoDataValue": (ctypes.c_double, [P, ctypes.POINTER(ctypes.c_int)]),
    "GDALGetProjectionRef": (ctypes.c_char_p, [P]),
    "GDALGetDriverByName": (P, [ctypes.c_char_p]),
    "GDALCreate": (P, [P, ctypes.c_char_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int, P]),
    "GDALDatasetCreateLayer": (P, [P, ctypes.c_char_p, P, ctypes.c_int, P]),
    "GDALDatasetStartTransaction": (ctypes.c_int, [P, ctypes.c_int]),
    "GDALDatasetCommitTransaction": (ctypes.c_int, [P]),
    "GDALDatasetExecuteSQL": (P, [P, ctypes.c_char_p, P, ctypes.c_char_p]),
    "GDALContourGenerateEx": (ctypes.c_int, [P, P, P, P, P]),
    "OGR_Fld_Create": (P, [ctypes.c_char_p, ctypes.c_int]),
    "OGR_Fld_Destroy": (None, [P]),
    "OGR_L_CreateField": (ctypes.c_int, [P, P, ctypes.c_int]),
    "OGR_L_GetFeatureCount": (ctypes.c_longlong, [P, ctypes.c_int]),
    "OSRNewSpatialReference": (P, [ctypes.c_char_p]),
    "OSRRelease": (None, [P]),
    "CPLGetLastErrorMsg": (ctypes.c_char_p, []),
    "CPLErrorReset": (None, []),
    "CPLGetLastErrorType": (ctypes.c_int, []),
}


def library_paths() -> list[str]:
    """Where rasterio's GDAL may be: its wheel's bundled library, else a system one."""
    import ctypes.util

    import rasterio

    here = Path(rasterio.__file__).parent
    found = []
    for folder in (here.parent / "rasterio.libs", here / ".dylibs", here):
        libs = (p for p in folder.glob("*gdal*") if p.suffix in (".so", ".dylib", ".dll") or ".so." in p.name)
        found += sorted(map(str, libs))
    system = ctypes.util.find_library("gdal")
    return found + ([system] if system else [])


def _strings(items: list[str]) -> ctypes.Array:
    """A NULL-terminated ``char **``."""
    return (ctypes.c_char_p * (len(items) + 1))(*[s.encode() for s in items], None)


class Gdal:
    """The C functions of :data:`SIGNATURES` in rasterio's GDAL."""

    def __init__(self) -> None:
        import rasterio  # noqa: F401  (loads its GDAL, registers its drivers' data paths)

        lib = None
        for path in library_paths():
            try:
                lib = ctypes.CDLL(path)
                lib.GDALContourGenerateEx  # noqa: B018
                break
            except (OSError, AttributeError):
                lib = None
        if lib is None:
            raise SoilVolumeError("contours: no GDAL library with GDALContourGenerateEx found beside rasterio")
        for name, (res, args) in SIGNATURES.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
        self.lib = lib
        lib.GDALAllRegister()

    def fail(self, what: str) -> SoilVolumeError:
        msg = (self.lib.CPLGetLastErrorMsg() or b"").decode(errors="replace").strip()
        return SoilVolumeError(f"{what}: {msg or 'GDAL failed'}")

    def contours(self, path: str, rasters: list, options_for: Callable, kind_sql: str) -> dict[str, int]:
        """Write ``path`` (GeoPackage) with a layer of contours per (name, raster) of ``rasters``
        (``options_for(nodata)``: GDALContourGenerateEx's options); {name: line count}."""
        lib = self.lib
        lib.CPLErrorReset()
        out = lib.GDALCreate(lib.GDALGetDriverByName(b"GPKG"), path.encode(), 0, 0, 0, GDT_UNKNOWN, None)
        if not out:
            raise self.fail(path)
        try:
            counts = {name: self._layer(out, name, str(tif), options_for) for name, tif in rasters}
            if "difference" in counts:
                lib.GDALDatasetExecuteSQL(out, kind_sql.encode(), None, None)
        finally:
            lib.CPLErrorReset()
            lib.GDALClose(out)
        if lib.CPLGetLastErrorType() >= CE_FAILURE:
            raise self.fail(path)
        return counts

    def _layer(self, out, name: str, tif: str, options_for: Callable) -> int:
        lib = self.lib
        src = lib.GDALOpen(tif.encode(), GA_READONLY)
        if not src:
            raise self.fail(tif)
        try:
            band, ok = lib.GDALGetRasterBand(src, 1), ctypes.c_int(0)
            nodata = lib.GDALGetRasterNoDataValue(band, ctypes.byref(ok))
            wkt = lib.GDALGetProjectionRef(src)
            srs = lib.OSRNewSpatialReference(wkt) if wkt else None
            layer = lib.GDALDatasetCreateLayer(out, name.encode(), srs, WKB_LINESTRING, None)
            if srs:
                lib.OSRRelease(srs)
            if not layer:
                raise self.fail(f"contours layer {name}")
            fields = [("ID", OFT_INTEGER), ("ELEV", OFT_REAL)]
            for field, kind in fields + ([("change", OFT_STRING)] if name == "difference" else []):
                defn = lib.OGR_Fld_Create(field.encode(), kind)
                lib.OGR_L_CreateField(layer, defn, 1)
                lib.OGR_Fld_Destroy(defn)
            opts = _strings(options_for(nodata if ok.value else None))
            lib.GDALDatasetStartTransaction(out, 0)
            if lib.GDALContourGenerateEx(band, layer, opts, None, None):
                raise self.fail(f"contours of {tif}")
            lib.GDALDatasetCommitTransaction(out)
            return int(lib.OGR_L_GetFeatureCount(layer, 1))
        finally:
            lib.GDALClose(src)
