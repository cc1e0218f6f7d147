"""readers.las, readers.ply, readers.pcd, readers.text: files to a :class:`PointView`."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pyproj

from ...core.types import short_error
from ...inputs import io
from ...inputs.lasheader import BoundsCheck, check_las_header
from .view import PointView, StageContext

SRS_OPTS = {"override_srs", "spatialreference", "default_srs"}
COMMON = {"filename", "count"} | SRS_OPTS
LAS_OPTS = COMMON
PLY_OPTS = COMMON
TEXT_OPTS = COMMON | {"header", "separator", "skip"}

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
    """Apply override_srs (synonym spatialreference) / default_srs as PDAL readers do."""
    override = ctx.string(opts, "override_srs") or ctx.string(opts, "spatialreference")
    default = ctx.string(opts, "default_srs")
    if override and default:
        raise ctx.error("can't use both 'override_srs' and 'default_srs'")
    text = override or (default if not view.srs_wkt else None)
    if text:
        try:
            view.srs_wkt = pyproj.CRS.from_user_input(text).to_wkt()
        except pyproj.exceptions.CRSError as exc:
            raise ctx.error(f"cannot understand SRS '{text[:80]}' ({exc})") from exc
    count = ctx.integer(opts, "count")
    if count is not None and count < len(view):
        view = view.take(np.arange(max(count, 0)))
    return view


def read_las(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """LAS/LAZ with laspy: X, Y, Z, Classification, ReturnNumber, NumberOfReturns, Intensity."""
    import laspy

    path = _path(opts, ctx)
    try:
        check_las_header(path)
    except io.SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    names = {
        "X": "x",
        "Y": "y",
        "Z": "z",
        "Classification": "classification",
        "ReturnNumber": "return_number",
        "NumberOfReturns": "number_of_returns",
        "Intensity": "intensity",
    }
    try:
        with laspy.open(path) as reader:
            header = reader.header
            wkt = io.las_crs_wkt(header, path)
            n = header.point_count
            present = set(header.point_format.dimension_names)
            cols = {k: v for k, v in names.items() if v in present or k in "XYZ"}
            arrays = {
                k: np.empty(n, dtype=np.float64 if k in "XYZ" else (np.uint16 if k == "Intensity" else np.uint8))
                for k in cols
            }
            start = 0
            bounds = BoundsCheck(path, header)
            for chunk in reader.chunk_iterator(2_000_000):
                m = len(chunk)
                if start + m > n:
                    raise io.SoilVolumeError(f"{path}: corrupt LAS file (more points than the header's {n})")
                for k, v in cols.items():
                    arrays[k][start : start + m] = np.asarray(getattr(chunk, v))
                bounds.update(
                    np.c_[
                        arrays["X"][start : start + m], arrays["Y"][start : start + m], arrays["Z"][start : start + m]
                    ]
                )
                start += m
            bounds.finish()
    except Exception as exc:  # laspy raises many types on broken files
        if isinstance(exc, io.SoilVolumeError):
            raise ctx.error(str(exc)) from exc
        raise ctx.error(f"{path}: not a readable LAS/LAZ file ({short_error(exc)})") from exc
    if start != n:
        raise ctx.error(f"{path}: corrupt LAS file (header says {n} points, read {start})")
    return _srs(PointView(arrays, wkt), opts, ctx)


def read_o3d(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """PLY/PCD vertices (x, y, z) through the engine's reader."""
    path = _path(opts, ctx)
    try:
        raw = io.read_points(path)
    except io.SoilVolumeError as exc:
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
    space separator means any run of whitespace. 'skip' lines are ignored first."""
    path = _path(opts, ctx)
    skip = ctx.integer(opts, "skip", 0) or 0
    header = ctx.string(opts, "header")
    sep_opt = ctx.string(opts, "separator")
    with open(path, encoding="utf-8", errors="replace") as fh:
        lines = [next(fh, "") for _ in range(skip + 1)]
    if header is None:
        header_line = lines[skip] if len(lines) > skip else ""
        skiprows = skip + 1
    else:
        header_line = header
        skiprows = skip
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
