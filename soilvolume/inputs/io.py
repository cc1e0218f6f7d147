"""Read and write point clouds: LAS/LAZ (laspy + lazrs), PLY/PCD (Open3D), XYZ/TXT/CSV (numpy).

Readers return absolute float64 coordinates in the file's own CRS and units; CRS handling lives in
:mod:`soilvolume.inputs.crs`. Writers go through a temporary name and rename when complete.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError, short_error
from ..soil.points import Signals
from .lasheader import BoundsCheck, check_las_header
from .lasimport import laspy_module

LAS_SUFFIXES = {".las", ".laz"}
GROUND = 2  # the LAS classification of ground points
O3D_SUFFIXES = {".ply", ".pcd"}
TEXT_SUFFIXES = {".xyz", ".txt", ".csv", ".pts"}
SUPPORTED = sorted(LAS_SUFFIXES | O3D_SUFFIXES | TEXT_SUFFIXES)


@dataclass
class RawPoints:
    """Points as read from a file: absolute coordinates in the file's CRS and units."""

    xyz: np.ndarray
    classification: np.ndarray | None
    crs_wkt: str | None
    path: str
    signals: Signals | None = None  # colour and returns, when the file has them


def _check_readable(path: Path) -> None:
    if not path.exists():
        raise SoilVolumeError(f"{path}: file not found")
    if not path.is_file():
        raise SoilVolumeError(f"{path}: not a file")
    if not os.access(path, os.R_OK):
        raise SoilVolumeError(f"{path}: file is not readable (permissions)")
    if path.suffix.lower() not in SUPPORTED:
        raise SoilVolumeError(
            f"{path}: unsupported point cloud format '{path.suffix}' (use one of {', '.join(SUPPORTED)})"
        )
    if path.suffix.lower() in LAS_SUFFIXES:
        check_las_header(path)


def read_points(path: str | os.PathLike) -> RawPoints:
    """Read a point cloud file; raise :class:`SoilVolumeError` naming the file on any problem."""
    p = Path(path)
    _check_readable(p)
    suffix = p.suffix.lower()
    if suffix in LAS_SUFFIXES:
        raw = _read_las(p)
    elif suffix in O3D_SUFFIXES:
        raw = _read_o3d(p)
    else:
        raw = _read_text(p)
    validate(raw)
    return raw


def validate(raw: RawPoints) -> None:
    """Reject empty clouds and non-finite coordinates."""
    if raw.xyz.shape[0] == 0:
        raise SoilVolumeError(f"{raw.path}: the point cloud is empty (0 points)")
    bad = ~np.isfinite(raw.xyz).all(axis=1)
    if bad.any():
        raise SoilVolumeError(f"{raw.path}: {int(bad.sum())} point(s) have NaN or infinite coordinates")


CRS_RECORDS = {2111, 2112, 34735, 34736, 34737}  # WKT (math transform, CRS) and GeoTIFF keys
WKT_STARTS = (b"PROJCS", b"PROJCRS", b"GEOGCS", b"GEOGCRS", b"COMPD_CS", b"COMPOUNDCRS", b"GEODCRS")


def las_crs_wkt(header, path: Path) -> str | None:
    """The CRS of a LAS header (WKT VLR or GeoTIFF keys) as WKT, or None when it has no CRS
    record; a CRS record that cannot be read is an error, not 'no CRS'."""
    try:
        crs = header.parse_crs()
    except Exception as exc:  # laspy raises several types on broken VLRs
        raise SoilVolumeError(f"{path}: the CRS stored in the header cannot be read ({short_error(exc)})") from exc
    if crs is None:
        broken = next((v for v in header.vlrs if _looks_like_crs(v)), None)
        if broken is not None:
            user = "".join(c if c.isprintable() else "?" for c in str(broken.user_id))
            raise SoilVolumeError(
                f"{path}: the header's CRS record (VLR '{user}' {broken.record_id}) cannot be read (corrupt header?)"
            )
        return None
    return crs.to_wkt()


def _looks_like_crs(vlr) -> bool:
    """A VLR that was meant to hold the CRS: its ids, or WKT-looking content."""
    from difflib import SequenceMatcher

    user = str(getattr(vlr, "user_id", "")).strip("\x00 ")
    if SequenceMatcher(None, user.lower(), "lasf_projection").ratio() > 0.8 or vlr.record_id in CRS_RECORDS:
        return True
    data = getattr(vlr, "record_data", b"") or b""
    return bytes(data[:16]).lstrip().upper().startswith(WKT_STARTS)


def _read_las(path: Path) -> RawPoints:
    laspy = laspy_module()

    try:
        with laspy.open(path) as reader:
            header = reader.header
            wkt = las_crs_wkt(header, path)
            n = header.point_count
            has_cls = "classification" in set(header.point_format.dimension_names)
    except SoilVolumeError:
        raise
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc
    xyz = np.empty((n, 3))
    cls = np.empty(n, dtype=np.uint8) if has_cls else None
    start = 0
    for part, part_cls in las_chunks(path, n, 2_000_000):  # raises unless exactly n points come
        if start + len(part) > n:
            raise SoilVolumeError(f"{path}: corrupt LAS file (more points than the header's {n})")
        xyz[start : start + len(part)] = part
        if cls is not None:
            cls[start : start + len(part)] = part_cls
        start += len(part)
    return RawPoints(xyz, cls, wkt, str(path))


def las_chunks(
    path: Path, count: int, size: int, signals: bool | Callable = False, origin: np.ndarray | None = None
) -> Iterator[tuple]:
    """(absolute xyz float64, classification or None) of a LAS/LAZ file, ``size`` points at a
    time; a point count other than the header's ``count`` is reported as a corrupt file. With
    ``signals``, a third item: the points' colour and returns (:func:`point_signals`; a function:
    of the dimensions it names for each chunk's classification, see :func:`signal_dims`).
    With ``origin``, the coordinates are ``xyz - origin`` (the subtraction done in the decoding)."""
    laspy = laspy_module()

    read = 0
    try:
        with laspy.open(path) as reader:
            h = reader.header
            dims = set(h.point_format.dimension_names)
            has_cls = "classification" in dims
            bounds = BoundsCheck(path, h)
            for chunk in reader.chunk_iterator(size):
                xyz, lo, hi = decoded_xyz(chunk, origin)
                if len(xyz):
                    bounds.extend(lo, hi)
                read += len(chunk)
                cls = np.array(chunk.classification) if has_cls else None  # a copy: a view pins the record
                item = (xyz, cls, point_signals(chunk, signal_dims(dims, signals, cls))) if signals else (xyz, cls)
                del chunk, xyz, cls  # the record is not held while the consumer works (or the queue is full)
                yield item
    except SoilVolumeError:
        raise
    except Exception as exc:
        raise SoilVolumeError(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc
    if read != count:
        raise SoilVolumeError(f"{path}: corrupt LAS file (header says {count} points, read {read})")
    bounds.finish()


def signal_dims(dims: set[str], signals, cls: np.ndarray | None) -> set[str]:
    """The dimensions of ``dims`` a read with ``signals`` returns for a chunk of classification
    ``cls``: all (True), or those ``signals(cls)`` names."""
    return dims if signals is True else dims & set(signals(cls))


def scaled_xyz(chunk) -> np.ndarray:
    """(N, 3) float64 coordinates of a laspy point record: ``X * scale + offset`` as laspy computes them."""
    return decoded_xyz(chunk)[0]


BLOCK = 1 << 14  # points decoded at a time: a block's column stays in the cache through its passes


def decoded_xyz(chunk, origin: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xyz, lo, hi) of a laspy point record: the (N, 3) float64 coordinates ``X * scale + offset``
    as laspy computes them (minus ``origin`` when given, as ``xyz - origin`` would), and the
    per-axis min and max of ``X * scale + offset`` (the absolute coordinates), block by block
    through a small scratch column (one pass over memory instead of one per operation)."""
    n = len(chunk)
    xyz = np.empty((n, 3))
    if n == 0:
        return xyz, np.full(3, np.inf), np.full(3, -np.inf)
    ints = [chunk.array[name] for name in "XYZ"]
    scratch = np.empty(min(n, BLOCK))
    lows, highs = np.empty((3, -(-n // BLOCK))), np.empty((3, -(-n // BLOCK)))
    with np.errstate(over="ignore", invalid="ignore"):  # checked against the bounds by the caller
        for b, start in enumerate(range(0, n, BLOCK)):
            stop = min(n, start + BLOCK)
            t = scratch[: stop - start]
            for k in range(3):
                np.multiply(ints[k][start:stop], chunk.scales[k], out=t)
                np.add(t, chunk.offsets[k], out=t)
                lows[k, b], highs[k, b] = t.min(), t.max()
                if origin is None:
                    xyz[start:stop, k] = t
                else:
                    np.subtract(t, origin[k], out=xyz[start:stop, k])
    return xyz, lows.min(axis=1), highs.max(axis=1)


def point_signals(record, dims: set[str]) -> Signals | None:
    """The colour (red, green, blue) and return numbers of a laspy point record, when its point
    format has them (None when it has neither)."""
    rgb = ret = None
    if {"red", "green", "blue"} <= dims:
        rgb = np.column_stack([np.asarray(record.red), np.asarray(record.green), np.asarray(record.blue)])
    if {"return_number", "number_of_returns"} <= dims:
        ret = np.column_stack([np.asarray(record.return_number), np.asarray(record.number_of_returns)]).astype(np.uint8)
    return None if rgb is None and ret is None else Signals(rgb, ret)


def _read_o3d(path: Path) -> RawPoints:
    import open3d as o3d

    pcd = o3d.io.read_point_cloud(str(path))
    xyz = np.asarray(pcd.points, dtype=np.float64)
    if xyz.size == 0 and path.stat().st_size > 0:
        raise SoilVolumeError(f"{path}: not a readable {path.suffix} point cloud (Open3D read 0 points)")
    sig = None
    if pcd.has_colors():  # 0..1 floats: to the 16-bit scale of LAS colour
        sig = Signals(np.rint(np.asarray(pcd.colors) * 65535).astype(np.uint16))
    return RawPoints(xyz.copy(), None, None, str(path), sig)


def _read_text(path: Path) -> RawPoints:
    delim = "," if path.suffix.lower() == ".csv" else None
    try:
        data = np.loadtxt(path, delimiter=delim, usecols=(0, 1, 2), ndmin=2, comments=("#", "//"))
    except ValueError:
        try:  # a header line
            data = np.loadtxt(path, delimiter=delim, usecols=(0, 1, 2), ndmin=2, skiprows=1)
        except Exception as exc:
            raise SoilVolumeError(f"{path}: cannot parse x y z columns ({exc})") from exc
    return RawPoints(np.asarray(data, dtype=np.float64), None, None, str(path))


@contextmanager
def atomic_path(final: str | os.PathLike) -> Iterator[Path]:
    """Yield a hidden temporary sibling path (named for this process, so a killed run's is
    recognised by :func:`soilvolume.core.outputs.sweep`); rename it onto ``final`` only if the block
    succeeds."""
    from ..core.outputs import STAGING, sibling

    final = Path(final)
    tmp = sibling(final, STAGING, suffix=final.suffix)
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_las_chunked(
    path: str | os.PathLike,
    chunks: Iterable[tuple[np.ndarray, np.ndarray | None]],
    origin: np.ndarray,
    crs_wkt: str | None,
    transform: np.ndarray | None = None,
    scale: float = 0.001,
) -> None:
    """Write (local xyz, classification or None) chunks, optionally through a 4x4 rigid
    ``transform``, as absolute LAS 1.4/LAZ (memory bounded by a chunk), atomically."""
    laspy = laspy_module()
    import pyproj

    header = laspy.LasHeader(point_format=6, version="1.4")
    origin = np.asarray(origin, float)
    header.offsets = np.floor(origin)
    header.scales = np.array([scale, scale, scale])
    if crs_wkt:
        header.add_crs(pyproj.CRS.from_wkt(crs_wkt))
    with atomic_path(path) as tmp:
        with laspy.open(tmp, mode="w", header=header, do_compress=Path(path).suffix.lower() == ".laz") as w:
            for xyz, cls in chunks:
                part = np.asarray(xyz, dtype=np.float64)
                if transform is not None:
                    part = part @ transform[:3, :3].T + transform[:3, 3]
                rec = laspy.ScaleAwarePointRecord.zeros(len(part), header=header)
                rec.x, rec.y, rec.z = part[:, 0] + origin[0], part[:, 1] + origin[1], part[:, 2] + origin[2]
                if cls is not None:
                    rec.classification = cls
                w.write_points(rec)


def write_las(
    path: str | os.PathLike,
    xyz_abs: np.ndarray,
    crs_wkt: str | None,
    classification: np.ndarray | None = None,
    scale: float = 0.001,
) -> None:
    """Write absolute coordinates as LAS 1.4 (LAZ when the suffix is .laz), atomically."""
    laspy = laspy_module()
    import pyproj

    header = laspy.LasHeader(point_format=6, version="1.4")
    lo = np.floor(xyz_abs.min(axis=0)) if len(xyz_abs) else np.zeros(3)
    header.offsets = lo
    header.scales = np.array([scale, scale, scale])
    if crs_wkt:
        header.add_crs(pyproj.CRS.from_wkt(crs_wkt))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz_abs[:, 0], xyz_abs[:, 1], xyz_abs[:, 2]
    if classification is not None:
        las.classification = classification
    with atomic_path(path) as tmp:
        las.write(str(tmp), do_compress=Path(path).suffix.lower() == ".laz")
