"""The STAC fields a ``.vpc`` is read by (PDAL wrench's ``vpc-spec.md``), checked field by field: one
error naming the file, the item and the field. A ``FeatureCollection`` of items: an optional ``id``,
``assets`` (the data asset: key or role ``data``, with an ``href``), optional ``properties``
(``pc:count``, ``proj:bbox``, ``proj:wkt2``/``projjson``/``epsg``) and WGS 84 ``bbox``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..core.types import SoilVolumeError


@dataclass(frozen=True)
class Item:
    """One validated item of a VPC; ``name``: how messages name it, ``features[3] ('tile_3')``."""

    name: str
    href: str
    count: int | None
    proj_bbox: tuple[float, ...] | None
    crs: Any  # the CRS of the first CRS field given (pyproj), or None
    bbox: tuple[float, ...] | None


def _clip(text: str, limit: int = 60) -> str:
    text = "".join(c if c.isprintable() else "?" for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


KINDS = ((type(None), "null"), (bool, "a boolean"), (int | float, "a number"), (str, "a string"))
KINDS += ((list, "a list"), (dict, "an object"))


def _kind(value: Any) -> str:
    """The JSON type of ``value`` as a word (never its content)."""
    return next((word for kind, word in KINDS if isinstance(value, kind)), type(value).__name__)


def items(path, doc: Any) -> list[Item]:
    """The validated items of a parsed ``.vpc`` document (see module)."""

    def fail(where: str, problem: str) -> SoilVolumeError:
        return SoilVolumeError(f"{path}: {where} {problem}")

    if not isinstance(doc, dict):
        raise fail("the document", f"must be a STAC FeatureCollection object (got {_kind(doc)})")
    if doc.get("type") != "FeatureCollection":
        raise fail("'type'", 'must be "FeatureCollection" (not a virtual point cloud)')
    features = doc.get("features")
    if not isinstance(features, list):
        raise fail("'features'", f"must be a list of items (got {_kind(features)})")
    if not features:
        raise fail("'features'", "is empty: the virtual point cloud has no tiles")
    return [_item(fail, k, f) for k, f in enumerate(features)]


def _item(fail, k: int, f: Any) -> Item:
    where = f"features[{k}]"
    if not isinstance(f, dict):
        raise fail(where, f"must be an object (got {_kind(f)})")
    ident = f.get("id", "")
    if not isinstance(ident, str | int) or isinstance(ident, bool):
        raise fail(f"{where}.id", f"must be a string (got {_kind(ident)})")
    if str(ident):
        where = f"{where} ('{_clip(str(ident))}')"
    if f.get("type", "Feature") != "Feature":
        raise fail(f"{where}.type", 'must be "Feature"')
    props = {} if f.get("properties") is None else f["properties"]
    if not isinstance(props, dict):
        raise fail(f"{where}.properties", f"must be an object (got {_kind(props)})")
    return Item(
        where,
        _href(fail, where, f.get("assets")),
        _count(fail, where, props.get("pc:count")),
        _box(fail, f"{where}.properties.proj:bbox", props.get("proj:bbox"), wgs84=False),
        _crs(fail, where, props),
        _box(fail, f"{where}.bbox", f.get("bbox"), wgs84=True),
    )


def _href(fail, where: str, assets: Any) -> str:
    if not isinstance(assets, dict) or not assets:
        raise fail(f"{where}.assets", f"must be an object of assets (got {_kind(assets)})")
    for key, asset in assets.items():
        if not isinstance(asset, dict):
            raise fail(f"{where}.assets.{_clip(str(key))}", f"must be an object (got {_kind(asset)})")
        roles = asset.get("roles", [])
        if not isinstance(roles, list) or not all(isinstance(r, str) for r in roles):
            raise fail(f"{where}.assets.{_clip(str(key))}.roles", "must be a list of strings")
    data = assets.get("data") or next((a for a in assets.values() if "data" in a.get("roles", [])), None)
    if data is None:
        raise fail(f"{where}.assets", "has no data asset (key 'data' or role 'data')")
    href = data.get("href")
    if not isinstance(href, str) or not href.strip():
        raise fail(f"{where}: the data asset's href", f"must be a non-empty string (got {_kind(href)})")
    if "\0" in href:
        raise fail(f"{where}: the data asset's href", "holds a NUL character")
    return href


def _count(fail, where: str, value: Any) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value) or value < 0:
        shown = f"{value:g}" if isinstance(value, float) and math.isfinite(value) else _kind(value)
        raise fail(f"{where}.properties.pc:count", f"must be a non-negative integer (got {shown})")
    return int(value)


def _box(fail, where: str, value: Any, wgs84: bool) -> tuple[float, ...] | None:
    if value is None:
        return None
    ok = isinstance(value, list) and len(value) in (4, 6)
    ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok:
        got = f"{len(value)} values" if isinstance(value, list) else _kind(value)
        raise fail(where, f"must be a list of 4 or 6 finite numbers (got {got})")
    box = tuple(float(v) for v in value)
    half = len(box) // 2
    if any(lo > hi for lo, hi in zip(box[:half], box[half:], strict=True)) and not wgs84:
        raise fail(where, "must list the minima before the maxima (a minimum is above its maximum)")
    if wgs84:
        lon, lat = box[0::half], box[1::half]
        if not all(-180 <= v <= 180 for v in lon) or not all(-90 <= v <= 90 for v in lat) or lat[0] > lat[1]:
            raise fail(where, "must be WGS 84 longitudes and latitudes (out of range)")
    return box


def _crs(fail, where: str, props: dict) -> Any:
    """The first CRS field given (``proj:wkt2``, ``proj:projjson``, ``proj:epsg``), parsed; each one
    given type-checked (a CRS that cannot be read is named, never ignored)."""
    import pyproj

    given = []
    for key, kinds, word in (
        ("proj:wkt2", str, "a WKT string"),
        ("proj:projjson", dict, "a PROJJSON object"),
        ("proj:epsg", int, "a positive integer"),
    ):
        value = props.get(key)
        if value is None or value == "":
            continue
        if not isinstance(value, kinds) or isinstance(value, bool) or (key == "proj:epsg" and value <= 0):
            raise fail(f"{where}.properties.{key}", f"must be {word} (got {_kind(value)})")
        given.append((key, value))
    if not given:
        return None
    key, value = given[0]
    try:
        return pyproj.CRS.from_user_input(f"EPSG:{value}" if key == "proj:epsg" else value)
    except (pyproj.exceptions.CRSError, TypeError, ValueError):
        raise fail(f"{where}.properties.{key}", "is not a CRS pyproj can read") from None
