"""Read and write point clouds: LAS/LAZ (laspy + lazrs), PLY/PCD (Open3D), XYZ/TXT/CSV (numpy).
Readers return absolute float64 coordinates in the file's CRS and units; writers rename when done. Two
inputs that must be different surveys: one file given twice (the same path, a symbolic or hard link to it,
or a byte-for-byte copy) compares a survey with itself, 0 ± 0 m3, and is refused."""

from __future__ import annotations

import filecmp
import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.outputs import STAGING, sibling
from ..core.types import SoilVolumeError
from ..soil.points import Signals
from .lasheader import check_las_header
from .lasread import las_header
from .records import las_chunks

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
    raw = (_read_las if suffix in LAS_SUFFIXES else _read_o3d if suffix in O3D_SUFFIXES else _read_text)(p)
    validate(raw)
    return raw


def validate(raw: RawPoints) -> None:
    """Reject empty clouds and non-finite coordinates."""
    if raw.xyz.shape[0] == 0:
        raise SoilVolumeError(f"{raw.path}: the point cloud is empty (0 points)")
    bad = ~np.isfinite(raw.xyz).all(axis=1)
    if bad.any():
        raise SoilVolumeError(f"{raw.path}: {int(bad.sum())} point(s) have NaN or infinite coordinates")


def sameness(a: Path, b: Path) -> str | None:
    """How ``b`` is ``a``: "is the same file as" (a path or link to it), "is a byte-for-byte copy of", or None."""
    try:
        if os.path.samefile(a, b):
            return "is the same file as"
        if a.is_file() and b.is_file() and filecmp.cmp(a, b, shallow=False):
            return "is a byte-for-byte copy of"
    except OSError:  # missing or unreadable: the reading says so
        return None
    return None


def check_two_surveys(before: Path, after: Path, what: str = "the before survey") -> None:
    """Refuse an ``after`` that is ``before`` (see :func:`sameness`), naming both files."""
    how = sameness(Path(before), Path(after))
    if how:
        raise SoilVolumeError(
            f"{after}: {how} {what} {before}; before and after must be two surveys of the site at different times"
        )


def _read_las(path: Path) -> RawPoints:
    wkt, n, _, _, has_cls, _ = las_header(path)
    xyz, cls, start = np.empty((n, 3)), np.empty(n, dtype=np.uint8) if has_cls else None, 0
    for part, part_cls in las_chunks(path, n, 2_000_000):  # raises unless exactly n points come
        xyz[start : start + len(part)] = part  # filled in place: no second copy of the cloud
        if cls is not None:
            cls[start : start + len(part)] = part_cls
        start += len(part)
    return RawPoints(xyz, cls, wkt, str(path))


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
    """A hidden sibling path (named for this process: ``core.outputs.sweep`` knows a killed run's),
    renamed onto ``final`` only if the block succeeds."""
    final = Path(final)
    tmp = sibling(final, STAGING, suffix=final.suffix)
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


def _write(path: str | os.PathLike, offsets: np.ndarray, scale: float, crs_wkt: str | None, chunks: Iterable) -> None:
    """Absolute (xyz, classification or None) chunks as LAS 1.4 point format 6 with these offsets, one
    scale for x/y/z and the CRS (LAZ when the suffix is .laz), atomically."""
    import laspy
    import pyproj  # here: the command line's start-up imports this module, not pyproj

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = offsets
    header.scales = np.array([scale, scale, scale])
    if crs_wkt:
        header.add_crs(pyproj.CRS.from_wkt(crs_wkt))
    with atomic_path(path) as tmp:
        with laspy.open(tmp, mode="w", header=header, do_compress=Path(path).suffix.lower() == ".laz") as w:
            for xyz, cls in chunks:
                rec = laspy.ScaleAwarePointRecord.zeros(len(xyz), header=header)
                rec.x, rec.y, rec.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
                if cls is not None:
                    rec.classification = cls
                w.write_points(rec)


def write_las_chunked(
    path: str | os.PathLike,
    chunks: Iterable[tuple[np.ndarray, np.ndarray | None]],
    origin: np.ndarray,
    crs_wkt: str | None,
    transform: np.ndarray,
) -> None:
    """Write (local xyz, classification) chunks, through a rigid ``transform``, as LAS 1.4/LAZ atomically."""
    origin = np.asarray(origin, float)
    rot, shift = transform[:3, :3].T, transform[:3, 3]
    absolute = ((np.asarray(xyz, dtype=np.float64) @ rot + shift + origin, cls) for xyz, cls in chunks)
    _write(path, np.floor(origin), 0.001, crs_wkt, absolute)


def write_las(
    path: str | os.PathLike,
    xyz_abs: np.ndarray,
    crs_wkt: str | None,
    classification: np.ndarray | None = None,
    scale: float = 0.001,
) -> None:
    """Write absolute coordinates as LAS 1.4 (LAZ when the suffix is .laz), atomically."""
    lo = np.floor(xyz_abs.min(axis=0)) if len(xyz_abs) else np.zeros(3)
    _write(path, lo, scale, crs_wkt, [(xyz_abs, classification)])
