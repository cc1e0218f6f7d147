"""Virtual point clouds (``.vpc``): STAC ItemCollections of point cloud tiles, as PDAL wrench's
``build_vpc`` and QGIS write them. The structure is checked by :mod:`vpcschema`; each tile's header
is read once and must match the VPC's box (``proj:bbox``, else the WGS 84 ``bbox``) and count; all
tiles share one CRS; only the tiles meeting a query box are read."""

from __future__ import annotations

import json
import nturl2path
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse

import numpy as np

from ..core.types import SoilVolumeError, short_error
from .lasheader import check_las_header
from .lasread import las_header
from .vpcschema import items


@dataclass(frozen=True)
class Tile:
    """One data file of a VPC: absolute path, point count and x/y/z box in the VPC's CRS."""

    path: str
    count: int
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True)
class Vpc:
    """A parsed virtual point cloud."""

    path: str
    crs_wkt: str | None
    tiles: tuple[Tile, ...]

    @property
    def count(self) -> int:
        return sum(t.count for t in self.tiles)


MAX_BYTES = 256 * 2**20  # a .vpc lists tiles: far larger is not one
#: how far a tile's box in the VPC may differ from its header's: native boxes (proj:bbox) are
#: copied from the header, WGS 84 ones are rounded degrees of a reprojected box
NATIVE_TOL, WGS84_TOL = 0.01, 1.0


def read_vpc(path: str | os.PathLike) -> Vpc:
    """Parse and check a ``.vpc`` (see module; errors name the file, the item and the field or tile),
    cached per version of it and its tiles (tile tasks open it often)."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise SoilVolumeError(f"{p}: file not found") from None
    except OSError as exc:
        raise SoilVolumeError(f"{p}: cannot be read ({exc.strerror})") from None
    version = (st.st_size, st.st_mtime_ns, st.st_ino)
    vpc, tiles = _read_vpc(str(p), *version)
    if [_version(t.path) for t in vpc.tiles] != tiles:  # a tile changed since: read it all again
        _read_vpc.cache_clear()
        vpc, _ = _read_vpc(str(p), *version)
    return vpc


def _version(path: str) -> tuple[int, int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns, st.st_ino


@lru_cache(maxsize=16)
def _read_vpc(path: str, size: int, mtime_ns: int, inode: int) -> tuple[Vpc, list]:
    p = Path(path)
    if p.is_dir() or not p.is_file():
        raise SoilVolumeError(f"{p}: not a regular file")
    if size > MAX_BYTES:
        raise SoilVolumeError(f"{p}: {size / 2**20:.0f} MB is far larger than any virtual point cloud")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else short_error(exc)
        raise SoilVolumeError(f"{p}: not a readable virtual point cloud ({why})") from None
    first, tiles, seen = None, [], {}  # first: the first tile with a CRS, its CRS and path
    for item in items(p, doc):
        tile_path = _href(p, item)
        if tile_path in seen:
            raise SoilVolumeError(f"{p}: {item.name} lists the tile {item.href} that {seen[tile_path]} lists already")
        seen[tile_path] = item.name
        tile, crs = _tile(p, item, tile_path)
        tiles.append(tile)
        if crs is not None and first is None:
            first = crs, tile_path
        elif crs is not None and not crs.equals(first[0]):
            raise SoilVolumeError(
                f"{p}: tiles in different CRSs ({Path(first[1]).name}: {first[0].name}; "
                f"{Path(tile_path).name}: {crs.name}); reproject them to one CRS first"
            )
    return Vpc(str(p), first and first[0].to_wkt(), tuple(tiles)), [_version(t.path) for t in tiles]


def file_url_path(url: str, windows: bool = os.name == "nt") -> str:
    """The local path of a ``file://`` URL: on Windows a drive letter or a host's UNC path; elsewhere a
    host other than localhost is another computer (ValueError)."""
    parts = urlparse(url)
    host = "" if parts.netloc.lower() == "localhost" else parts.netloc
    if windows:
        path = nturl2path.url2pathname(parts.path)
        return f"\\\\{unquote(host)}{path}" if host else path
    if host:
        raise ValueError(f"on another computer ({host})")
    return unquote(parts.path)


def _href(vpc: Path, item) -> str:
    """An item's data asset as an absolute path (relative to the VPC), a readable regular file."""
    href = item.href
    if href.startswith("file://"):
        try:
            href = file_url_path(href)
        except ValueError as exc:
            raise SoilVolumeError(f"{vpc}: {item.name}: tile {href} is {exc}: only local files are read") from None
    elif "://" in href:
        raise SoilVolumeError(f"{vpc}: {item.name}: remote tile {href} is not supported (only local files)")
    full = (vpc.parent / href).resolve()
    if not full.exists():
        raise SoilVolumeError(f"{vpc}: tile {href} not found ({full})")
    if full.is_dir():
        raise SoilVolumeError(f"{vpc}: tile {href} is a folder, not a LAS/LAZ file")
    if not full.is_file():
        raise SoilVolumeError(f"{vpc}: tile {href} is not a regular file (a device or pipe)")
    if not os.access(full, os.R_OK):
        raise SoilVolumeError(f"{vpc}: tile {href} is not readable (permissions)")
    if full.suffix.lower() not in (".las", ".laz"):
        raise SoilVolumeError(f"{vpc}: tile {href} is not a LAS/LAZ file (its name does not end in .las or .laz)")
    return str(full)


def _tile(vpc: Path, item, tile_path: str) -> tuple[Tile, Any]:
    """The tile with its header's box and count (the header checked before laspy reads it), the VPC's
    checked against them; and its CRS (the VPC's, else the header's, or None)."""
    import pyproj

    check_las_header(Path(tile_path))
    wkt, count, lo, hi, _, _ = las_header(Path(tile_path))
    lo, hi, name = tuple(map(float, lo)), tuple(map(float, hi)), Path(tile_path).name
    crs = item.crs if item.crs is not None else None if wkt is None else pyproj.CRS.from_wkt(wkt)
    if item.count is not None and item.count != count:
        raise SoilVolumeError(f"{vpc}: {item.name}: pc:count {item.count} but the header of {name} says {count} points")
    if item.proj_bbox is not None:
        _check_box(vpc, item, name, "proj:bbox", item.proj_bbox, lo, hi, NATIVE_TOL, exact=True)
    elif item.bbox is not None and crs is not None:
        b = item.bbox
        box = _box_to("EPSG:4326", crs, *((b[0], b[1], b[3], b[4]) if len(b) == 6 else b))
        _check_box(vpc, item, name, "bbox (WGS 84)", box, lo, hi, WGS84_TOL, exact=False)
    return Tile(tile_path, count, lo, hi), crs


def _check_box(vpc: Path, item, name: str, field: str, box, lo, hi, tol: float, exact: bool) -> None:
    """The VPC's x/y box of a tile against its header's: equal within ``tol`` (and 1e-9 relative), or
    holding it unless ``exact``."""
    box = list(box)
    half = len(box) // 2
    blo, bhi = np.asarray(box[:2]), np.asarray(box[half : half + 2])
    hlo, hhi = np.asarray(lo[:2]), np.asarray(hi[:2])
    t = tol + 1e-9 * np.maximum(np.abs(hlo), np.abs(hhi))
    outside = (hlo < blo - t).any() or (hhi > bhi + t).any()
    if outside or (exact and ((blo < hlo - t).any() or (bhi > hhi + t).any())):
        shown = " ".join(f"{v:.2f}" for v in (*hlo, *hhi))
        raise SoilVolumeError(
            f"{vpc}: {item.name}: its {field} does not match the header of {name} (x/y box {shown}): "
            "rebuild the virtual point cloud"
        )


def _box_to(src, dst, w: float, s: float, e: float, n: float) -> list[float]:
    """The x/y box w, s, e, n in ``src`` as one in ``dst`` (densified edges)."""
    import pyproj

    return list(pyproj.Transformer.from_crs(src, dst, always_xy=True).transform_bounds(w, s, e, n, densify_pts=21))


def write_vpc(path: str | os.PathLike, tiles: list[str | os.PathLike], relative: bool = True) -> Path:
    """Write a ``.vpc`` of LAS/LAZ/COPC ``tiles`` from their headers (hrefs relative unless not ``relative``)."""
    import laspy

    out = Path(path)
    ext = ("pointcloud/v1.0.0", "projection/v1.1.0")
    features = []
    for t in map(Path, tiles):
        with laspy.open(t) as r:
            h = r.header
            crs = h.parse_crs()
        href = os.path.relpath(t.resolve(), out.resolve().parent) if relative else str(t.resolve())
        props = {"datetime": "1970-01-01T00:00:00Z", "pc:count": int(h.point_count), "pc:type": "lidar"}
        props |= {"pc:encoding": "?", "proj:bbox": [*map(float, h.mins), *map(float, h.maxs)]}
        feature = {"type": "Feature", "stac_version": "1.0.0", "id": t.stem}
        if crs is not None:
            props["proj:wkt2"] = crs.to_wkt()
            w, s, e, n = _box_to(crs, "EPSG:4326", *map(float, (*h.mins[:2], *h.maxs[:2])))
            feature["bbox"] = [w, s, float(h.mins[2]), e, n, float(h.maxs[2])]  # GeoJSON: WGS 84
        feature["stac_extensions"] = [f"https://stac-extensions.github.io/{e}/schema.json" for e in ext]
        feature |= {"geometry": None, "properties": props}
        features.append({**feature, "assets": {"data": {"href": href.replace(os.sep, "/"), "roles": ["data"]}}})
    out.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=1))
    return out
