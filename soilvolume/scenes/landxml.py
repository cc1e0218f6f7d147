"""A design GeoTIFF's pixel centres written as a LandXML TIN (two triangles per square of four
centres): linear inside each triangle, it is the same design as the GeoTIFF's bilinear
resampling to the difference of bilinear and linear within a pixel (nil on a plane)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

NS = "http://www.landxml.org/schema/LandXML-1.2"
FEET = {"foot": 0.3048, "USSurveyFoot": 1200.0 / 3937.0}


def tin_of(tif: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) x, y, z in the raster's units, faces (m, 3) 0-based) of a GeoTIFF's valid centres."""
    import rasterio

    with rasterio.open(tif) as ds:
        z, t = ds.read(1).astype(np.float64), ds.transform
    rows, cols = z.shape
    cc, rr = np.meshgrid(np.arange(cols) + 0.5, np.arange(rows) + 0.5)
    x, y = t.c + t.a * cc.ravel(), t.f + t.e * rr.ravel()  # north-up
    idx = np.arange(rows * cols).reshape(rows, cols)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.r_[np.c_[a, b, d], np.c_[a, d, c]]
    zz = z.ravel()
    faces = faces[np.isfinite(zz[faces]).all(axis=1)]
    return np.c_[x, y, zz], faces


def write_landxml(
    path: str | Path,
    points: np.ndarray,
    faces: np.ndarray,
    *,
    unit: str = "meter",
    epsg: int | None = None,
    name: str = "design",
    namespace: str = NS,
) -> Path:
    """Write ``points`` (x, y, z in metres) and ``faces`` (0-based) as a LandXML 1.2 TIN surface:
    ``P`` as "northing easting elevation" in ``unit`` (meter, foot, USSurveyFoot), ids from 1."""
    f = FEET.get(unit, 1.0)
    system = "Imperial" if unit in FEET else "Metric"
    crs = "" if epsg is None else f'  <CoordinateSystem name="design" epsgCode="{epsg}"/>\n'
    pts = "\n".join(f'<P id="{i + 1}">{y / f:.6f} {x / f:.6f} {z / f:.6f}</P>' for i, (x, y, z) in enumerate(points))
    tris = "\n".join(f"<F>{a + 1} {b + 1} {c + 1}</F>" for a, b, c in faces)
    xmlns = f' xmlns="{namespace}"' if namespace else ""
    text = (
        f'<?xml version="1.0" encoding="UTF-8"?>\n<LandXML{xmlns} version="1.2">\n'
        f'  <Units><{system} linearUnit="{unit}" areaUnit="squareMeter" volumeUnit="cubicMeter"/></Units>\n{crs}'
        f'  <Surfaces><Surface name="{name}"><Definition surfType="TIN">\n<Pnts>\n{pts}\n</Pnts>\n'
        f"<Faces>\n{tris}\n</Faces>\n</Definition></Surface></Surfaces>\n</LandXML>\n"
    )
    Path(path).write_text(text)
    return Path(path)
