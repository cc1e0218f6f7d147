"""Design surfaces for the tests: a seeded pair's before ground (or a graded pad) as a
single-band DEM GeoTIFF, what a design or an earlier DEM is to ``soilvolume estimate DESIGN.tif
AFTER.laz`` (the truth of the pair is then the truth against the surface), and a design
GeoTIFF's pixel centres as a LandXML TIN (two triangles per square of four centres: linear
inside each triangle, the same design as the GeoTIFF's bilinear resampling to the difference
of bilinear and linear within a pixel, nil on a plane)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rasterio
from affine import Affine

from soilvolume.dem.geotiff import Layout, write_geotiff
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.features import after_box, change_dz
from soilvolume.scenes.world import World

NS = "http://www.landxml.org/schema/LandXML-1.2"
FEET = {"foot": 0.3048, "USSurveyFoot": 1200.0 / 3937.0}


@dataclass(frozen=True)
class Pad:
    """A grading plan: a flat pad over a rectangle (centre at fractions ``fx``, ``fy`` of the after
    footprint, half-sides in m) at ``level`` m above the terrain at its centre, its side slopes
    (``slope`` rise per run) graded to the existing ground, which the plan keeps elsewhere."""

    fx: float = 0.3
    fy: float = 0.7
    half_x: float = 10.0
    half_y: float = 7.0
    level: float = 0.0
    slope: float = 0.5

    def heights(self, world: World, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The plan's heights (m, local) at local x/y."""
        x0, y0, x1, y1 = after_box(world.cfg)
        cx, cy = x0 + self.fx * (x1 - x0), y0 + self.fy * (y1 - y0)
        d = np.hypot(np.maximum(np.abs(x - cx) - self.half_x, 0.0), np.maximum(np.abs(y - cy) - self.half_y, 0.0))
        z = float(world.terrain(np.array([cx]), np.array([cy]))[0]) + self.level
        return np.clip(world.terrain(x, y), z - self.slope * d, z + self.slope * d)


def pad_truth(seed: int, config: SceneConfig, pad: Pad, res: float = 0.05) -> dict:
    """net, cut, fill (m³) of the after survey's true ground against the plan ``pad`` over the
    after footprint: a midpoint sum on ``res`` cells of the analytic surfaces (the piles' and
    the pad's kinks make it converge as res², well below 0.05 % at 5 cm)."""
    world = World(seed, config)
    x0, y0, x1, y1 = after_box(config)
    xs = np.arange(x0 + res / 2, x1, res)
    out = {"net": 0.0, "cut": 0.0, "fill": 0.0}
    for y in np.arange(y0 + res / 2, y1, res):
        yy = np.full(xs.shape, y)
        d = world.terrain(xs, yy) + change_dz(xs, yy, config, seed) - pad.heights(world, xs, yy)
        out["fill"] += float(d[d > 0].sum()) * res * res
        out["cut"] -= float(d[d < 0].sum()) * res * res
    out["net"] = out["fill"] - out["cut"]
    return out


def write_surface(
    path: str | Path,
    seed: int,
    config: SceneConfig,
    *,
    cell: float = 0.5,
    offset_m: float = 0.0,
    crs: str | None = "",
    bands: int = 1,
    unit: str = "metre",
    shift_xy: tuple[float, float] = (0.0, 0.0),
    pad: Pad | None = None,
) -> Path:
    """Write the before epoch's ground of ``(seed, config)`` over the before survey's box as a
    GeoTIFF of ``cell`` pixels, heights at the pixel centres plus ``offset_m`` (a datum error);
    ``crs``: "" the scene's, None none; ``bands`` > 1 repeats the band (a bad input);
    ``unit``: the band's declared unit (heights are converted to it); ``shift_xy``: the raster
    placed that far off (m, e.g. away from the survey); ``pad``: a grading plan instead of the
    before ground."""
    world = World(seed, config)
    (w, h), o = config.before_size, config.origin
    cols, rows = int(np.ceil(w / cell)), int(np.ceil(h / cell))
    x = (np.arange(cols) + 0.5) * cell
    y = h - (np.arange(rows) + 0.5) * cell
    xx, yy = np.meshgrid(x, y)
    ground = world.terrain if pad is None else (lambda px, py: pad.heights(world, px, py))
    z = ground(xx.ravel(), yy.ravel()).reshape(rows, cols) + o[2] + offset_m
    z = z / 0.3048 if unit in ("ft", "foot", "feet") else z
    transform = Affine(cell, 0.0, o[0] + shift_xy[0], 0.0, -cell, o[1] + shift_xy[1] + h)
    crs = config.crs if crs == "" else crs
    layout = Layout(cols, rows, transform, crs, "float32", float("nan"), bands, units=(unit,) * bands)
    return write_geotiff(path, [z] * bands, layout)


def tin_of(tif: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) x, y, z in the raster's units, faces (m, 3) 0-based) of a GeoTIFF's valid centres."""
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
