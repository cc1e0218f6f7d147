"""readers.las, readers.ply, readers.pcd, readers.text: files to a :class:`PointView`; writers.las
through :func:`soilvolume.inputs.io.write_las`."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...core.types import SoilVolumeError
from ...inputs import io
from ...inputs.stream import open_source
from .view import PointView, StageContext

_KNOWN = {
    n.lower(): n
    for n in ("X", "Y", "Z", "Classification", "Intensity", "ReturnNumber", "NumberOfReturns", "Red", "Green", "Blue")
}


def _path(opts: dict, ctx: StageContext) -> Path:
    path = Path(opts["filename"])  # a reader's filename, checked by load.normalise
    if not path.is_file():
        raise ctx.error(f"{path}: file not found")
    return path


def _srs(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """Apply default_srs as PDAL readers do: the file's own SRS wins."""
    text = opts.get("default_srs")
    if text and not view.srs_wkt:
        view.srs_wkt = ctx.crs(text, "").to_wkt()
    return view


def read_file(view: PointView | None, opts: dict, ctx: StageContext) -> PointView:
    """LAS/LAZ (X, Y, Z, Classification, returns) and PLY/PCD (X, Y, Z) by the engine's readers."""
    path = _path(opts, ctx)
    try:
        raw = open_source(path).materialize()
    except SoilVolumeError as exc:
        raise ctx.error(str(exc)) from exc
    arrays = {d: raw.xyz[:, k].copy() for k, d in enumerate("XYZ")}
    if raw.classification is not None:
        arrays["Classification"] = raw.classification.astype(np.uint8)
    returns = None if raw.signals is None else raw.signals.returns
    if returns is not None:
        arrays["ReturnNumber"], arrays["NumberOfReturns"] = returns[:, 0].copy(), returns[:, 1].copy()
    return _srs(PointView(arrays, raw.crs_wkt), opts, ctx)


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
    """Delimited text as PDAL reads it: dimensions named by the first line (or 'header'), split by
    its first non-alphanumeric character (or 'separator'; a space: any whitespace)."""
    path = _path(opts, ctx)
    header_line, skiprows = opts.get("header"), 0
    if header_line is None:
        with open(path, encoding="utf-8", errors="replace") as fh:
            header_line, skiprows = next(fh, ""), 1
    names, sep = _split_header(header_line, opts.get("separator"))
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


def write_las(view: PointView, opts: dict, ctx: StageContext) -> PointView:
    """LAS 1.4 / LAZ by suffix; one scale for X/Y/Z (PDAL's default 0.01), automatic offsets."""
    name = opts.get("filename")
    if not name:
        raise ctx.error("option 'filename' is required")
    if "#" in name:
        raise ctx.error("'#' placeholders (one file per view) need PDAL")
    path = Path(name)
    scales = {ctx.number(opts, f"scale_{a}", 0.01) for a in "xyz"}
    if len(scales) != 1:
        raise ctx.error("different scale_x/scale_y/scale_z need PDAL")
    try:
        io.write_las(path, view.xyz, view.srs_wkt, view.arrays.get("Classification"), scale=scales.pop())
    except OSError as exc:
        raise ctx.error(f"{path}: cannot write ({exc})") from exc
    return view
