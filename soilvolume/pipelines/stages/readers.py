"""readers.las, readers.ply, readers.pcd, readers.text: files to a :class:`PointView`."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pyproj

from ...core.types import SoilVolumeError, short_error
from ...inputs import io
from ...inputs.lasheader import BoundsCheck, check_las_header
from .view import PointView, StageContext

LAS_OPTS = {"filename", "default_srs"}
PLY_OPTS = LAS_OPTS
TEXT_OPTS = LAS_OPTS | {"header", "separator"}

_KNOWN = {
    n.lower(): n
    for n in ("X", "Y", "Z", "Classification", "Intensity", "ReturnNumber", "NumberOfReturns", "Red", "Green", "Blue")
}


def _path(opts: dict, ctx: StageContext) -> Path:
    name = ctx.string(opts, "filename")
    if not name:
        raise ctx.error("option 'filename' is required")
    path = Path(name)
    if not path.is_file():
        raise ctx.error(f"{path}: file not found")
    return path


def _srs(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Apply default_srs as PDAL readers do: the file's own SRS wins."""
    text = ctx.string(opts, "default_srs")
    if text and not view.srs_wkt:
        try:
            view.srs_wkt = pyproj.CRS.from_user_input(text).to_wkt()
        except pyproj.exceptions.CRSError as exc:
            raise ctx.error(f"cannot understand SRS '{text[:80]}' ({exc})") from exc
    return view


#: the LAS dimensions read: PDAL's name -> laspy's
_LAS_DIMS = {
    "X": "x",
    "Y": "y",
    "Z": "z",
    "Classification": "classification",
    "ReturnNumber": "return_number",
    "NumberOfReturns": "number_of_returns",
    "Intensity": "intensity",
}


def _las_arrays(reader, path: Path) -> tuple[dict[str, np.ndarray], int]:
    """The dimensions of an open LAS/LAZ file read in chunks, each chunk checked against the
    header's box; returns the arrays and the number of points read."""
    header = reader.header
    n = header.point_count
    present = set(header.point_format.dimension_names)
    cols = {k: v for k, v in _LAS_DIMS.items() if v in present or k in "XYZ"}
    dtypes = {"Intensity": np.uint16, "X": np.float64, "Y": np.float64, "Z": np.float64}
    arrays = {k: np.empty(n, dtype=dtypes.get(k, np.uint8)) for k in cols}
    start = 0
    bounds = BoundsCheck(path, header)
    for chunk in reader.chunk_iterator(2_000_000):
        end = start + len(chunk)
        if end > n:
            raise SoilVolumeError(f"{path}: corrupt LAS file (more points than the header's {n})")
        for k, v in cols.items():
            arrays[k][start:end] = np.asarray(getattr(chunk, v))
        bounds.update(np.c_[arrays["X"][start:end], arrays["Y"][start:end], arrays["Z"][start:end]])
        start = end
    bounds.finish()
    return arrays, start


def read_las(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """LAS/LAZ with laspy: X, Y, Z, Classification, ReturnNumber, NumberOfReturns, Intensity."""
    import laspy

    path = _path(opts, ctx)
    try:
        check_las_header(path)
        with laspy.open(path) as reader:
            wkt = io.las_crs_wkt(reader.header, path)
            n = reader.header.point_count
            arrays, read = _las_arrays(reader, path)
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    except Exception as exc:  # laspy raises many types on broken files
        raise ctx.error(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc
    if read != n:
        raise ctx.error(f"{path}: corrupt LAS file (header says {n} points, read {read})")
    return _srs(PointView(arrays, wkt), opts, ctx)


def read_o3d(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """PLY/PCD vertices (x, y, z) through the engine's reader."""
    path = _path(opts, ctx)
    try:
        raw = io.read_points(path)
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    arrays = {"X": raw.xyz[:, 0].copy(), "Y": raw.xyz[:, 1].copy(), "Z": raw.xyz[:, 2].copy()}
    return _srs(PointView(arrays, None), opts, ctx)


def _split_header(line: str, sep: str | None) -> tuple[list[str], str]:
    line = line.strip()
    if line.startswith('"'):
        names = re.findall(r'"([^"]*)"', line)
        rest = re.sub(r'"[^"]*"', "", line).strip()
        found = rest[0] if rest else " "
    else:
        m = re.search(r"[^A-Za-z0-9_]", line)
        found = m.group(0) if m else " "
        names = line.split(found) if found != " " else line.split()
    sep = sep or found
    return [n.strip() for n in names if n.strip()], sep


def read_text(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """Delimited text as PDAL reads it: a header line names the dimensions (or option 'header'),
    fields split by the header's first non-alphanumeric character (or option 'separator'); a
    space separator means any run of whitespace."""
    path = _path(opts, ctx)
    header_line = ctx.string(opts, "header")
    skiprows = 0
    if header_line is None:
        with open(path, encoding="utf-8", errors="replace") as fh:
            header_line, skiprows = next(fh, ""), 1
    sep_opt = ctx.string(opts, "separator")
    names, sep = _split_header(header_line, sep_opt)
    dims = [_KNOWN.get(n.lower(), n) for n in names]
    if not {"X", "Y", "Z"} <= set(dims):
        raise ctx.error(f"{path}: the header '{header_line.strip()[:80]}' does not name X, Y and Z")
    delim = None if sep.isspace() else sep
    try:
        data = np.loadtxt(path, delimiter=delim, skiprows=skiprows, ndmin=2, dtype=np.float64, comments=None)
    except ValueError as exc:
        raise ctx.error(f"{path}: cannot parse the point records ({exc})") from exc
    if data.size and data.shape[1] != len(dims):
        raise ctx.error(f"{path}: lines have {data.shape[1]} fields, the header names {len(dims)}")
    if data.size == 0:
        data = np.empty((0, len(dims)))
    arrays = {d: data[:, i].copy() for i, d in enumerate(dims)}
    if "Classification" in arrays:
        arrays["Classification"] = arrays["Classification"].astype(np.uint8)
    return _srs(PointView(arrays, None), opts, ctx)
