"""One working frame for both clouds: the before cloud's projected CRS (a geographic one: its UTM
zone), x/y/z in metres, each file's horizontal and vertical units honoured (e.g. US survey feet)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyproj
from pyproj.aoi import AreaOfInterest
from pyproj.database import query_utm_crs_info

from ..core.types import SoilVolumeError, short_error


@dataclass(frozen=True)
class WorkFrame:
    """The CRS outputs are written in, and the unit factors to and from it."""

    crs: pyproj.CRS
    xy_unit: float  # metres per horizontal unit of ``crs``

    @property
    def wkt(self) -> str:
        return self.crs.to_wkt()


def parse_crs(text: str | None, what: str) -> pyproj.CRS | None:
    """A CRS from user text (EPSG code, 'EPSG:2991+6360', WKT, PROJ string) or header WKT."""
    if text is None or str(text).strip() == "":
        return None
    try:
        return pyproj.CRS.from_user_input(text)
    except pyproj.exceptions.CRSError as exc:
        shown = " ".join(str(text).split())
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        raise SoilVolumeError(f"{what}: cannot understand CRS '{shown}' ({short_error(exc)})") from exc


def horizontal(crs: pyproj.CRS) -> pyproj.CRS:
    """The horizontal part of a (possibly compound) CRS."""
    return crs.sub_crs_list[0] if crs.is_compound else crs


def raster_wkt(wkt: str | None) -> str | None:
    """WKT of the 2D horizontal part of ``wkt``: rasters hold metres, which a vertical CRS in feet would mislabel."""
    return horizontal(pyproj.CRS.from_user_input(wkt)).to_2d().to_wkt() if wkt else None


def has_vertical(crs: pyproj.CRS) -> bool:
    return crs.is_compound or crs.is_vertical or len(crs.axis_info) == 3


def xy_unit(crs: pyproj.CRS) -> float:
    """Metres per horizontal unit (1 for geographic: not used for lengths)."""
    h = horizontal(crs)
    return 1.0 if h.is_geographic else float(h.axis_info[0].unit_conversion_factor)


def z_unit(crs: pyproj.CRS) -> float:
    """Metres per vertical unit: the vertical CRS's axis, else (LAS convention) the horizontal unit."""
    if crs.is_compound:
        return float(crs.sub_crs_list[1].axis_info[0].unit_conversion_factor)
    if len(crs.axis_info) == 3:
        return float(crs.axis_info[2].unit_conversion_factor)
    return xy_unit(crs)


def work_frame(before: pyproj.CRS, lonlat_hint: tuple[float, float] | None = None) -> WorkFrame:
    """The working frame: the before CRS when projected, else the UTM zone at ``lonlat_hint``."""
    h = horizontal(before)
    if h.is_projected:
        return WorkFrame(before, xy_unit(before))
    if lonlat_hint is None:
        raise SoilVolumeError("a geographic before CRS needs a position to choose a UTM zone")
    lon, lat = lonlat_hint
    at = AreaOfInterest(lon, lat, lon, lat)
    infos = query_utm_crs_info(datum_name=h.datum.name if h.datum else "WGS 84", area_of_interest=at)
    infos = infos or query_utm_crs_info(datum_name="WGS 84", area_of_interest=at)
    if not infos:
        raise SoilVolumeError(f"no UTM zone found for lon/lat {lon:.4f}, {lat:.4f}")
    return WorkFrame(pyproj.CRS.from_epsg(int(infos[0].code)), 1.0)


def to_frame(xyz: np.ndarray, src: pyproj.CRS, frame: WorkFrame, path: str) -> np.ndarray:
    """Absolute coordinates in ``src`` to the frame, in metres: a 3D transformation when both CRSs
    have a vertical part (datum shifts are pyproj's), else z by the source's vertical unit."""
    dst = frame.crs
    out = np.empty_like(xyz, dtype=np.float64)
    if src.equals(dst):
        out[:, :2] = xyz[:, :2]
        out[:, 2] = xyz[:, 2] * z_unit(src)
    else:
        both_3d = has_vertical(src) and has_vertical(dst)
        s, d = (src, dst) if both_3d else (horizontal(src), horizontal(dst))
        try:
            tr = pyproj.Transformer.from_crs(s, d, always_xy=True)
        except pyproj.exceptions.ProjError as exc:
            raise SoilVolumeError(f"{path}: no transformation from its CRS to {d.name} ({exc})") from exc
        if both_3d:
            x, y, z = tr.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2], errcheck=False)
            out[:, 2] = np.asarray(z) * z_unit(dst)
        else:
            x, y = tr.transform(xyz[:, 0], xyz[:, 1], errcheck=False)
            out[:, 2] = xyz[:, 2] * z_unit(src)
        out[:, 0], out[:, 1] = x, y
        if not np.isfinite(out).all():
            raise SoilVolumeError(f"{path}: CRS transformation to {dst.name} failed (points outside its area of use?)")
    out[:, :2] *= frame.xy_unit
    return out


def lonlat_of(xyz: np.ndarray, crs: pyproj.CRS) -> tuple[float, float]:
    """Longitude/latitude of the centre of a cloud's bounding box."""
    cx, cy = ((xyz[:, :2].min(axis=0) + xyz[:, :2].max(axis=0)) / 2).tolist()
    lon, lat = pyproj.Transformer.from_crs(horizontal(crs), "EPSG:4326", always_xy=True).transform(cx, cy)
    return float(lon), float(lat)


def frame_box(lo: np.ndarray, hi: np.ndarray, crs: pyproj.CRS, frame: WorkFrame, path: str) -> tuple:
    """The box lo..hi of a file's header (its CRS and units) in the working frame (absolute, metres)."""
    corners = np.array([[x, y, lo[2]] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])] + [list(hi)], float)
    corners = to_frame(corners, crs, frame, path)
    return corners.min(axis=0), corners.max(axis=0)


def to_local(crs: pyproj.CRS, frame: WorkFrame, origin: np.ndarray, path: str):
    """File CRS -> local frame; a plain :class:`Shift` when already in the frame's CRS in metres."""
    if crs.equals(frame.crs) and frame.xy_unit == 1.0 and z_unit(crs) == 1.0:
        return Shift(origin)
    return lambda xyz: to_frame(xyz, crs, frame, path) - origin


class Shift:
    """File -> local frame in the frame's CRS in metres: ``xyz - origin``; :meth:`inplace` on a chunk
    the reader allocated (no 24 MB array per 1 M points to fault in), or by a reader as it decodes."""

    def __init__(self, origin: np.ndarray) -> None:
        self.origin = origin

    def __call__(self, xyz: np.ndarray) -> np.ndarray:
        return xyz - self.origin

    def inplace(self, xyz: np.ndarray) -> np.ndarray:
        return np.subtract(xyz, self.origin, out=xyz)
