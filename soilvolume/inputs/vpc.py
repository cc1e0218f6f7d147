"""Virtual point clouds (``.vpc``): a STAC ItemCollection of point cloud tiles, as written by
PDAL wrench ``build_vpc`` and QGIS "Build virtual point cloud" (``vpc-spec.md`` in PDAL/wrench).

Each tile's box comes from ``proj:bbox`` (native CRS), else from the WGS 84 ``bbox``, else from
its LAS header; only the tiles meeting a query box are read. All tiles must share one CRS.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np

from ..core.types import SoilVolumeError


@dataclass(frozen=True)
class Tile:
    """One data file of a VPC: absolute path, point count and x/y/z box in the VPC's CRS."""

    path: str
    count: int
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def meets(self, lo, hi) -> bool:
        """Whether the tile's x/y box meets the x/y box lo..hi."""
        return bool(self.lo[0] <= hi[0] and lo[0] <= self.hi[0] and self.lo[1] <= hi[1] and lo[1] <= self.hi[1])


@dataclass(frozen=True)
class Vpc:
    """A parsed virtual point cloud."""

    path: str
    crs_wkt: str | None
    tiles: tuple[Tile, ...]

    @property
    def count(self) -> int:
        return sum(t.count for t in self.tiles)

    @property
    def lo(self) -> np.ndarray:
        return np.min([t.lo for t in self.tiles], axis=0)

    @property
    def hi(self) -> np.ndarray:
        return np.max([t.hi for t in self.tiles], axis=0)

    def tiles_meeting(self, lo=None, hi=None) -> list[Tile]:
        """The tiles whose box meets the x/y box lo..hi (all when None)."""
        return [t for t in self.tiles if lo is None or t.meets(lo, hi)]


def read_vpc(path: str | os.PathLike) -> Vpc:
    """Parse a ``.vpc``; one-line errors name the file or the tile at fault."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise SoilVolumeError(f"{p}: file not found") from None
    except (OSError, ValueError) as exc:
        raise SoilVolumeError(f"{p}: not a readable virtual point cloud ({exc})") from exc
    items = doc.get("features") if isinstance(doc, dict) else None
    if doc.get("type") != "FeatureCollection" or not isinstance(items, list) or not items:
        raise SoilVolumeError(f"{p}: not a virtual point cloud (expected a STAC FeatureCollection of tiles)")
    crss, tiles = [], []
    for item in items:
        tile_path = _href(p, item)
        crs = _item_crs(item) or _header_crs(tile_path)
        crss.append((crs, tile_path))
        tiles.append(_tile(tile_path, item, crs))
    return Vpc(str(p), _common_crs(p, crss), tuple(tiles))


def _href(vpc: Path, item: dict) -> str:
    """The data asset of an item as an absolute path (relative hrefs are relative to the VPC)."""
    assets = item.get("assets") or {}
    data = assets.get("data") or next((a for a in assets.values() if "data" in a.get("roles", [])), None)
    if not data or not data.get("href"):
        raise SoilVolumeError(f"{vpc}: item '{item.get('id', '?')}' has no data asset href")
    href = data["href"]
    if href.startswith("file://"):
        href = unquote(urlparse(href).path)
    elif "://" in href:
        raise SoilVolumeError(f"{vpc}: remote tile {href} is not supported (only local files)")
    full = (vpc.parent / href).resolve()
    if not full.is_file():
        raise SoilVolumeError(f"{vpc}: tile {href} not found ({full})")
    if not os.access(full, os.R_OK):
        raise SoilVolumeError(f"{vpc}: tile {href} is not readable (permissions)")
    return str(full)


def _item_crs(item: dict):
    import pyproj

    props = item.get("properties") or {}
    for key in ("proj:wkt2", "proj:projjson", "proj:epsg"):
        value = props.get(key)
        if value:
            return pyproj.CRS.from_user_input(f"EPSG:{value}" if key == "proj:epsg" else value)
    return None


def _header_crs(tile_path: str):
    import laspy
    import pyproj

    try:
        with laspy.open(tile_path) as r:
            crs = r.header.parse_crs()
    except Exception as exc:
        raise SoilVolumeError(f"{tile_path}: not a readable LAS/LAZ tile ({exc})") from exc
    return None if crs is None else pyproj.CRS.from_user_input(crs)


def _common_crs(vpc: Path, crss: list) -> str | None:
    """The one CRS of all tiles (WKT), or an error naming two tiles that differ."""
    known = [(c, t) for c, t in crss if c is not None]
    if not known:
        return None
    first, first_tile = known[0]
    for crs, tile in known[1:]:
        if not crs.equals(first):
            raise SoilVolumeError(
                f"{vpc}: tiles in different CRSs ({Path(first_tile).name}: {first.name}; "
                f"{Path(tile).name}: {crs.name}); reproject them to one CRS first"
            )
    return first.to_wkt()


def _tile(tile_path: str, item: dict, crs) -> Tile:
    props = item.get("properties") or {}
    count = props.get("pc:count")
    box = props.get("proj:bbox")
    if box is None and item.get("bbox") is not None and crs is not None:
        box = _from_wgs84(item["bbox"], crs)
    if box is None or count is None:
        return _tile_from_header(tile_path)
    box = [float(v) for v in box]
    lo, hi = (box[:2] + [-np.inf], box[2:] + [np.inf]) if len(box) == 4 else (box[:3], box[3:])
    return Tile(tile_path, int(count), tuple(lo), tuple(hi))


def _from_wgs84(bbox: list, crs) -> list[float]:
    """A WGS 84 bbox (2D or 3D) as an x/y box in ``crs`` (densified edges)."""
    import pyproj

    b = [float(v) for v in bbox]
    w, s, e, n = (b[0], b[1], b[3], b[4]) if len(b) == 6 else b
    t = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    return list(t.transform_bounds(w, s, e, n, densify_pts=21))


def _to_wgs84(mins, maxs, crs) -> list[float]:
    """A native 3D box as a WGS 84 3D bbox (GeoJSON requires WGS 84 boundaries)."""
    import pyproj

    t = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    w, s, e, n = t.transform_bounds(float(mins[0]), float(mins[1]), float(maxs[0]), float(maxs[1]), densify_pts=21)
    return [w, s, float(mins[2]), e, n, float(maxs[2])]


def _tile_from_header(tile_path: str) -> Tile:
    import laspy

    try:
        with laspy.open(tile_path) as r:
            h = r.header
            return Tile(tile_path, int(h.point_count), tuple(map(float, h.mins)), tuple(map(float, h.maxs)))
    except Exception as exc:
        raise SoilVolumeError(f"{tile_path}: not a readable LAS/LAZ tile ({exc})") from exc


def write_vpc(path: str | os.PathLike, tiles: list[str | os.PathLike], relative: bool = True) -> Path:
    """Write a ``.vpc`` grouping LAS/LAZ/COPC ``tiles`` (boxes, counts and CRS from their headers;
    hrefs relative to the VPC unless ``relative`` is False)."""
    import laspy

    out = Path(path)
    features = []
    for t in map(Path, tiles):
        with laspy.open(t) as r:
            h = r.header
            crs = h.parse_crs()
        href = os.path.relpath(t.resolve(), out.resolve().parent) if relative else str(t.resolve())
        props = {
            "datetime": "1970-01-01T00:00:00Z",
            "pc:count": int(h.point_count),
            "pc:type": "lidar",
            "pc:encoding": "?",
            "proj:bbox": [*map(float, h.mins), *map(float, h.maxs)],
        }
        feature = {"type": "Feature", "stac_version": "1.0.0", "id": t.stem}
        if crs is not None:
            props["proj:wkt2"] = crs.to_wkt()
            feature["bbox"] = _to_wgs84(h.mins, h.maxs, crs)
        features.append(
            {
                **feature,
                "stac_extensions": [
                    "https://stac-extensions.github.io/pointcloud/v1.0.0/schema.json",
                    "https://stac-extensions.github.io/projection/v1.1.0/schema.json",
                ],
                "geometry": None,
                "properties": props,
                "assets": {"data": {"href": href.replace(os.sep, "/"), "roles": ["data"]}},
            }
        )
    out.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=1))
    return out
