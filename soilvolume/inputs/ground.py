"""The ground points of a whole cloud by the SMRF or cloth simulation filter (class 2 is streamed)."""

from __future__ import annotations

import pyproj

from ..core.types import SoilVolumeError
from ..options import Options
from .crs import xy_unit, z_unit
from .csf import DEFAULTS, csf_classify
from .io import RawPoints
from .smrf import smrf_classify
from .stream import Source, from_raw

SMRF_NOTE = "SMRF ground filter (window {window:g} m, slope {slope:g})"
CSF_NOTE = "cloth simulation filter (CSF: cloth {resolution:g} m, rigidness {rigidness}, {threshold:g} m)"


def filtered(src: Source, crs: pyproj.CRS, options: Options) -> tuple[Source, str, str | None]:
    """(source to stream, ground mode for streaming, note): SMRF (``filter``) with an earthworks
    window and slope (PDAL's 18 m / 0.15 take the piles for objects) or CSF, run in metres on the
    whole cloud."""
    if options.ground not in ("filter", "csf"):
        return src, options.ground, None
    raw = src.materialize()
    h, v = xy_unit(crs), z_unit(crs)
    x, y, z = raw.xyz[:, 0] * h, raw.xyz[:, 1] * h, raw.xyz[:, 2] * v
    if options.ground == "filter":
        keep = smrf_classify(x, y, z, window=options.ground_window, slope=options.ground_slope)
        note = SMRF_NOTE.format(window=options.ground_window, slope=options.ground_slope)
    else:
        keep, note = csf_classify(x, y, z, **DEFAULTS), CSF_NOTE.format(**DEFAULTS)
    if not keep.any():
        raise SoilVolumeError(f"{src.path}: the {note.split(' (')[0]} found no ground points")
    sig = None if raw.signals is None else raw.signals.select(keep)  # colour still says what is green
    out = from_raw(RawPoints(raw.xyz[keep], None, raw.crs_wkt, raw.path, sig))
    out.count = src.count  # report the points read, not the ground points
    return out, "filter", note
