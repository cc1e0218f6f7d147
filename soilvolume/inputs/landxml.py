"""A LandXML TIN design surface as the reference (Civil 3D, Trimble Business Center, Carlson,
Pix4Dmatic), read with the standard library's XML parser (namespace-agnostic), ``<Units>`` and
``<CoordinateSystem>`` honoured; its own ``<Faces>`` rasterised on a run's grid, linear inside each
triangle, nodata outside. LandXML points are ``northing easting elevation`` (y x z)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj

from ..core.types import GridSpec, SoilVolumeError, short_error
from .crs import WorkFrame, has_vertical, horizontal, parse_crs, raster_wkt, xy_unit
from .tinraster import rasterise

SUFFIXES = (".xml", ".landxml")
UNITS = {  # LandXML linearUnit -> metres
    "meter": 1.0,
    "metre": 1.0,
    "millimeter": 1e-3,
    "centimeter": 1e-2,
    "kilometer": 1e3,
    "foot": 0.3048,
    "ussurveyfoot": 1200.0 / 3937.0,
    "inch": 0.0254,
    "mile": 1609.344,
}


def is_landxml(path: str | Path | None) -> bool:
    """Whether ``path`` names a LandXML file (by its suffix)."""
    return path is not None and Path(path).suffix.lower() in SUFFIXES


@dataclass(frozen=True)
class Tin:
    """A LandXML TIN surface: x/y in its CRS's units, heights in metres, triangles as indices."""

    path: str
    name: str
    xy: np.ndarray  # (n, 2) easting, northing in the CRS's own units
    z: np.ndarray  # (n,) metres
    faces: np.ndarray  # (m, 3) indices into xy/z
    crs: pyproj.CRS
    unit: str  # the file's linearUnit
    surfaces: tuple[str, ...]  # every surface's name in the file
    masked: tuple[dict, ...] = ()

    @property
    def vertical_unit(self) -> str:
        return f"the LandXML file's Units ({self.unit})"

    @property
    def resolution_m(self) -> float:
        """The median edge length of its triangles (m)."""
        a, b = self.xy[self.faces], np.roll(self.xy[self.faces], 1, axis=1)
        per_unit = 111_320.0 if horizontal(self.crs).is_geographic else xy_unit(self.crs)  # a degree of latitude
        return float(np.median(np.hypot(*(a - b).reshape(-1, 2).T))) * per_unit

    def describe(self) -> dict:
        """report.json's description of the reference (``inputs.before`` and ``reference``)."""
        return {
            "kind": "surface",
            "format": "LandXML TIN",
            "path": self.path,
            "surface": self.name,
            "surfaces_in_file": list(self.surfaces),
            "crs": self.crs.name,
            "crs_wkt": self.crs.to_wkt(),
            "points": int(len(self.z)),
            "triangles": int(len(self.faces)),
            "linear_unit": self.unit,
            "resolution_m": self.resolution_m,
            "vertical_unit": self.vertical_unit,
            "masked_as_nodata": [],
        }


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _children(node: ET.Element, name: str) -> list[ET.Element]:
    """``node``'s children named ``name`` in ``node``'s own namespace (or none)."""
    prefix = node.tag[: node.tag.index("}") + 1] if node.tag.startswith("{") else ""
    return node.findall(prefix + name)


def _find(node: ET.Element, name: str) -> ET.Element | None:
    return next((c for c in node.iter() if _local(c.tag) == name), None)


def open_tin(path: Path, crs_override: str | None, name: str | None = None) -> Tin:
    """Read and check a LandXML file's surface (the first, or the one named ``name``)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise SoilVolumeError(f"{path}: cannot read it as LandXML ({short_error(exc)})") from exc
    surfaces = [s for group in _children(root, "Surfaces") for s in _children(group, "Surface")]
    names = tuple(s.get("name", f"#{i + 1}") for i, s in enumerate(surfaces))
    if not surfaces:
        raise SoilVolumeError(f"{path}: no <Surface> in this LandXML file (a TIN design surface is needed)")
    if name is not None and name not in names:
        raise SoilVolumeError(f"{path}: no surface named '{name}' (it has: {', '.join(names)})")
    surface = surfaces[names.index(name) if name is not None else 0]
    unit, factor = _units(root, path)
    crs = _crs(root, path, crs_override)
    ids, yxz = _points(surface, path)
    faces = _faces(surface, ids, path)
    xy = yxz[:, [1, 0]] * (1.0 if horizontal(crs).is_geographic else factor / xy_unit(crs))  # degrees as they are
    return Tin(str(path), names[surfaces.index(surface)], xy, yxz[:, 2] * factor, faces, crs, unit, names)


def _units(root: ET.Element, path: Path) -> tuple[str, float]:
    units = _find(root, "Units")
    system = next(iter(units), None) if units is not None else None
    if system is None:
        raise SoilVolumeError(f"{path}: no <Units> in this LandXML file (its linear unit is needed)")
    unit = system.get("linearUnit", "")
    factor = UNITS.get(unit.lower())
    if factor is None:
        raise SoilVolumeError(f"{path}: unknown LandXML linearUnit '{unit}' (meter, foot, USSurveyFoot, ...)")
    return unit, factor


def _crs(root: ET.Element, path: Path, override: str | None) -> pyproj.CRS:
    """The file's CRS (epsgCode, else ogcWktCode), else ``--before-crs``; both and differing: refused."""
    node = _find(root, "CoordinateSystem")
    text = None if node is None else (node.get("epsgCode") or node.get("ogcWktCode") or None)
    if text is not None and text.strip().isdigit():
        text = f"EPSG:{text.strip()}"
    own = parse_crs(text, f"{path}: its CoordinateSystem")
    missing = "the LandXML file declares no CRS (CoordinateSystem epsgCode or ogcWktCode)"
    return surface_crs(path, own, override, missing, ("the LandXML file's", "a file"))


def surface_crs(path, own: pyproj.CRS | None, override: str | None, missing: str, words: tuple, vertical=False):
    """A surface's ``own`` CRS, else ``--before-crs`` (also with ``vertical``, when that one has a
    vertical part); both and horizontally differing: refused. ``missing``, ``words``: the wording."""
    given = parse_crs(override, "{opt:before_crs}")
    if own is None and given is None:
        raise SoilVolumeError(f"{path}: {missing}; give {{opt:before_crs}} (e.g. EPSG:32654)")
    if own is not None and given is not None and not horizontal(own).equals(horizontal(given), ignore_axis_order=True):
        raise SoilVolumeError(
            f"{path}: {{opt:before_crs={override}}} differs from {words[0]} CRS ({own.name}); "
            f"{{opt:before_crs}} applies only to {words[1]} without one"
        )
    return given if own is None or (vertical and given is not None and has_vertical(given)) else own


def _points(surface: ET.Element, path: Path) -> tuple[list[str], np.ndarray]:
    """The surface's point ids and their (northing, easting, elevation), in the file's unit."""
    pnts = _find(surface, "Pnts")
    points = [] if pnts is None else _children(pnts, "P")
    if not points:
        raise SoilVolumeError(f"{path}: the surface has no points (<Pnts> with <P>)")
    texts = [p.text or "" for p in points]
    bad = next((i for i, t in enumerate(texts) if len(t.split()) != 3), None)
    try:
        values = np.array(" ".join(texts).split(), dtype=np.float64)
    except ValueError as exc:
        raise SoilVolumeError(f"{path}: a <P> point is not three numbers ({short_error(exc)})") from exc
    if bad is not None or not np.isfinite(values).all():
        shown = "" if bad is None else f" (point '{points[bad].get('id', bad + 1)}': '{' '.join(texts[bad].split())}')"
        raise SoilVolumeError(f"{path}: each <P> point must be three numbers 'northing easting elevation'{shown}")
    return [p.get("id", str(i + 1)) for i, p in enumerate(points)], values.reshape(-1, 3)


def _faces(surface: ET.Element, ids: list[str], path: Path) -> np.ndarray:
    """The surface's visible triangles (``<F>``; ``i="1"`` ones are holes, left out) as indices."""
    node = _find(surface, "Faces")
    faces = [f for f in ([] if node is None else _children(node, "F")) if f.get("i", "0") != "1"]
    if not faces:
        raise SoilVolumeError(f"{path}: the surface has no faces (<Faces> with <F>): a TIN is needed")
    texts = [f.text or "" for f in faces]
    bad = next((t for t in texts if len(t.split()) != 3), None)
    if bad is not None:
        raise SoilVolumeError(f"{path}: a face <F>{' '.join(bad.split())}</F> does not name three points")
    names = np.array(" ".join(texts).split())
    keys = np.array([pid.strip() for pid in ids])
    order = np.argsort(keys, kind="stable")
    pos = np.minimum(np.searchsorted(keys[order], names), len(keys) - 1)
    found = keys[order][pos] == names
    if not found.all():
        missing = names[~found][0]
        raise SoilVolumeError(f"{path}: a face names point '{missing}', which is not in the surface's <Pnts>")
    return order[pos].reshape(-1, 3).astype(np.int64)


def box(tin: Tin, frame_crs: pyproj.CRS, unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box (absolute x/y in the frame, metres) of the TIN's triangles."""
    xy = _in(tin, horizontal(frame_crs))[np.unique(tin.faces)] * unit
    if not np.isfinite(xy).all():
        raise SoilVolumeError(f"{tin.path}: its points cannot be transformed into {frame_crs.name}")
    return xy.min(axis=0), xy.max(axis=0)


def check_over(tin: Tin, lo: np.ndarray, hi: np.ndarray, frame: WorkFrame, margin_m: float) -> Tin:
    """``tin`` when its triangles' box meets the survey's box ``lo``..``hi`` (absolute, metres)."""
    t_lo, t_hi = box(tin, frame.crs, frame.xy_unit)
    if (t_hi < np.asarray(lo[:2]) - margin_m).any() or (t_lo > np.asarray(hi[:2]) + margin_m).any():
        raise SoilVolumeError(
            f"{tin.path} does not overlap the survey: its extent misses the survey's (check the CRSs)"
        )
    return tin


def on_grid(tin: Tin, grid: GridSpec) -> np.ndarray:
    """The TIN's heights (m) at ``grid``'s cell centres in its CRS, linear in each triangle, else NaN."""
    xy = _in(tin, pyproj.CRS.from_wkt(raster_wkt(grid.crs_wkt)))
    t = grid.transform  # north-up
    uv = np.c_[(xy[:, 0] - t.c) / t.a - 0.5, (xy[:, 1] - t.f) / t.e - 0.5]
    return rasterise(uv, tin.z, tin.faces, (grid.rows, grid.cols))


def _in(tin: Tin, crs: pyproj.CRS) -> np.ndarray:
    """The TIN's points' x/y in ``crs``'s units."""
    src = horizontal(tin.crs)
    if src.equals(horizontal(crs), ignore_axis_order=True):
        return tin.xy
    x, y = pyproj.Transformer.from_crs(src, horizontal(crs), always_xy=True).transform(
        tin.xy[:, 0], tin.xy[:, 1], errcheck=False
    )
    return np.c_[np.asarray(x, float), np.asarray(y, float)]
