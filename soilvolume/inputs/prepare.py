"""Step 1: both clouds streamed into one working frame (before CRS, metres, local origin), ground
selected (class 2 streamed, or the SMRF or cloth simulation filter on a whole cloud), the before
cropped to the after footprint plus the radius, both thinned on the way."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pyproj

from ..core.cells import bounds
from ..core.types import Cloud, SoilVolumeError
from ..core.wording import opt
from ..options import Options
from ..soil.points import PointRule
from .chunkwork import NOTHING  # a box no point is in
from .crs import WorkFrame, frame_box, lonlat_of, parse_crs, work_frame, xy_unit, z_unit
from .crs import to_local as _local
from .footprint import MIN_COLUMNS, PolygonMask, check_spread, footprint
from .io import RawPoints
from .smrf import DEFAULTS, csf_classify, smrf_classify
from .stream import ColumnThinner, Loaded, Source, from_raw, load

CLASS_NOTE = "class 2 (ground)"  # the selection note of a cloud streamed as class 2 only
SMRF_NOTE = "SMRF ground filter (window {window:g} m, slope {slope:g})"
CSF_NOTE = "cloth simulation filter (CSF: cloth {resolution:g} m, rigidness {rigidness}, {threshold:g} m)"
THIN_POINTS = 200_000  # registration subset: about this many after points


@dataclass(frozen=True)
class Prepared:
    """Both clouds in the local working frame (absolute = xyz + origin): full-resolution float32
    points and float64 column-thinned subsets for registration."""

    before: Cloud  # within the after box + the GPS error prior (the thinned subset: + radius)
    after: Cloud
    frame: WorkFrame
    origin: np.ndarray
    inputs: dict
    before_thin: np.ndarray
    after_thin: np.ndarray
    voxel: float
    after_chunks: Callable[[], Iterator[tuple[np.ndarray, np.ndarray | None]]]  # all after points, local
    read_s: float = 0.0  # of the streaming time, seconds spent reading and decoding chunks
    before_counts: np.ndarray | None = None  # points behind each before_thin centroid
    ground: tuple[bool, bool] = (False, False)  # (before, after) streamed as class 2 only
    index: tuple = (None, None)  # (before, after): chunk boxes of single files (Source.index)
    crop: np.ndarray | None = None  # the crop polygon: the after footprint buffered by the radius

    @property
    def rules(self) -> tuple:
        """(before, after): each epoch's ``soil.points.PointRule`` (None when none is active)."""
        return tuple(None if c.nonsoil is None else c.nonsoil.rule for c in (self.before, self.after))


def resolve_crs(raw: RawPoints | Source, override: str | None, flag: str) -> pyproj.CRS:
    """The file's header CRS, else the one given by ``flag``; a flag contradicting the header is refused."""
    given, header = parse_crs(override, flag), parse_crs(raw.crs_wkt, raw.path)
    if header is None and given is None:
        raise SoilVolumeError(f"{raw.path}: the file has no CRS in its header; pass {flag} (e.g. EPSG:32654)")
    if header is not None and given is not None and not header.equals(given, ignore_axis_order=True):
        raise SoilVolumeError(
            f"{raw.path}: {flag} {override} differs from the CRS in the header ({header.name}); {flag} "
            "applies only to files without one (to replace a wrong header CRS, prepare the cloud with a "
            "pipeline whose reader sets override_srs)"
        )
    return header or given


def prepare(
    before: Source, after: Source, options: Options, check=None, full: bool = True, loader: Callable[..., Loaded] = load
) -> Prepared:
    """Stream both clouds into the working frame: all after points, the before points within the
    radius of the after footprint, and thinned subsets of both (only these unless ``full``: the tiled
    engine reads points per tile). ``loader`` streams one source (:func:`stream.load`, or as tasks)."""
    crs_b = resolve_crs(before, options.before_crs, opt("before_crs"))
    crs_a = resolve_crs(after, options.after_crs, opt("after_crs"))
    frame = _own_frame(before, crs_b)
    origin, voxel, to_a, thinner = _setup(after, crs_a, frame)
    # the source streamed has the path and count of ``after``
    _, a, note_a = _load_whole(after, crs_a, to_a, thinner, options, check, None if full else NOTHING, loader)
    check_spread(a.thin[:, :2], after.path, "after the ground selection")
    poly = footprint(a.thin[:, :2], options.radius)
    before, b, note_b = _load_before(
        before, crs_b, frame, origin, poly, (after.path, a.thin), voxel, options, check, full, loader
    )
    return Prepared(
        Cloud(b.xyz, origin, frame.wkt, before.path, nonsoil=b.nonsoil),
        Cloud(a.xyz, origin, frame.wkt, after.path, nonsoil=a.nonsoil),
        frame,
        origin,
        {
            "before": _describe(before, crs_b, b, note_b or b.note),
            "after": _describe(after, crs_a, a, note_a or a.note),
        },
        b.thin,
        a.thin,
        voxel,
        _all_points(after, to_a),
        a.extra["read_s"] + b.extra["read_s"],
        b.extra["counts"],
        (b.note == CLASS_NOTE, a.note == CLASS_NOTE),
        (b.extra["index"], a.extra["index"]),
        poly,
    )


def _load_before(
    src: Source, crs: pyproj.CRS, frame: WorkFrame, origin, poly, after: tuple, voxel, options, check, full, loader
) -> tuple[Source, Loaded, str | None]:
    """The before cloud streamed within the after footprint ``poly``, at full resolution only where the
    after cloud (``after``: path, thinned points) can land (GPS prior + 2 m); refused without overlap."""
    after_path, after_thin = after
    if src.raw is None and crs.equals(frame.crs) and frame.xy_unit == 1.0 and z_unit(crs) == 1.0:
        src = src.within(poly.min(axis=0) + origin[:2], poly.max(axis=0) + origin[:2])  # its reads: the crop's box
    src, mode, note = filtered(src, crs, options)
    reach = options.max_gps_shift + 2.0
    lo_a, hi_a = bounds(after_thin, 2)
    box = (lo_a - reach, hi_a + reach) if full else NOTHING
    lo, hi = frame_box(src.lo, src.hi, crs, frame, src.path)  # its header box, padded below: every point lies in it
    pad = _pad(lo, hi)
    within = lo[:2] - origin[:2] - pad, hi[:2] - origin[:2] + pad  # a crop radius far past the data costs nothing
    thinner = ColumnThinner(poly.min(axis=0), poly.max(axis=0), voxel, within, src.path)
    local = _local(crs, frame, origin, src.path)
    b = loader(src, local, mode, PolygonMask(poly), thinner, check, box, not full, exclude=options.exclude)
    if b.used < MIN_COLUMNS:  # a handful of points in all: not an overlap problem
        raise SoilVolumeError(f"{src.path}: too few points to work with ({b.used}, at least {MIN_COLUMNS} needed)")
    if b.extra["cropped"] < 10 or (full and len(b.xyz) == 0):
        raise SoilVolumeError(
            f"{src.path} and {after_path} do not overlap: the before cloud has "
            f"{b.extra['cropped']} points within {options.radius:g} m of the after cloud's footprint "
            f"(check the CRSs and {opt('radius')})"
        )
    check_spread(b.thin[:, :2], src.path, "near the after cloud")
    return src, b, note


def prepare_survey(after: Source, options: Options, check=None) -> Prepared:
    """The after survey alone in its own working frame, as :func:`prepare` streams it, for a run
    whose reference is a surface: no before cloud."""
    crs_a = resolve_crs(after, options.after_crs, opt("after_crs"))
    streamed, a, note, frame, origin, voxel, to_a = _survey(after, crs_a, options, check, centred=True)
    none = np.empty((0, 3))
    return Prepared(
        Cloud(none.astype(np.float32), origin, frame.wkt, ""),
        Cloud(a.xyz, origin, frame.wkt, after.path, nonsoil=a.nonsoil),
        frame,
        origin,
        {"after": _describe(streamed, crs_a, a, note)},
        none,
        a.thin,
        voxel,
        _all_points(after, to_a),
        a.extra["read_s"],
        ground=(False, a.note == CLASS_NOTE),
        index=(None, a.extra["index"]),
    )


@dataclass(frozen=True)
class Single:
    """One cloud streamed into its working frame: float32 local points and a thinned subset."""

    xyz: np.ndarray
    thin: np.ndarray
    frame: WorkFrame
    origin: np.ndarray
    note: str


def prepare_single(src: Source, override: str | None, options: Options, check=None) -> Single:
    """Stream one cloud (ground selection as ``options.ground``) into its own working frame, with
    the local origin at the floor of its bounds."""
    crs = resolve_crs(src, override, opt("crs"))
    _, one, note, frame, origin, _, _ = _survey(src, crs, options, check, centred=False)
    return Single(one.xyz, one.thin, frame, origin, note)


def _survey(src: Source, crs: pyproj.CRS, options: Options, check, centred: bool) -> tuple:
    """One survey streamed whole into its own frame, refused without points left: (the source
    streamed, what was loaded, selection note, frame, origin, voxel, file -> local)."""
    frame = _own_frame(src, crs)
    origin, voxel, to_local, thinner = _setup(src, crs, frame, centred)
    streamed, one, note = _load_whole(src, crs, to_local, thinner, options, check)
    note = note or one.note
    if len(one.xyz) == 0:
        raise SoilVolumeError(f"{src.path}: no points left after the ground selection ({note})")
    check_spread(one.thin[:, :2], src.path, "after the ground selection")
    return streamed, one, note, frame, origin, voxel, to_local


def _setup(src: Source, crs: pyproj.CRS, frame: WorkFrame, centred: bool = True) -> tuple:
    """(local origin: the floor of the low corner of ``src`` in ``frame``, or of its x/y centre when
    ``centred``, thinning voxel, file -> local, the thinner over its local box padded (header bounds))."""
    lo, hi = frame_box(src.lo, src.hi, crs, frame, src.path)
    origin = np.floor(np.r_[(lo[:2] + hi[:2]) / 2, lo[2]]) if centred else np.floor(lo)
    area = max(float(np.prod(hi[:2] - lo[:2])), 1.0)
    voxel, pad = max(0.15, float(np.sqrt(area / THIN_POINTS))), _pad(lo, hi)  # about THIN_POINTS columns, >= 0.15 m
    thinner = ColumnThinner(lo - origin - pad, hi - origin + pad, voxel, name=src.path)
    return origin, voxel, _local(crs, frame, origin, src.path), thinner


def _own_frame(src: Source, crs: pyproj.CRS) -> WorkFrame:
    """The working frame of a run whose reference is ``src`` (a UTM zone for a geographic CRS)."""
    hint = lonlat_of(np.array([src.lo, src.hi]), crs) if crs.is_geographic else None
    return work_frame(crs, hint)


def _load_whole(
    src: Source, crs: pyproj.CRS, to_local, thinner: ColumnThinner, options: Options, check, box=None, loader=load
) -> tuple[Source, Loaded, str | None]:
    """(source streamed, loaded, filter note): every (ground) point of ``src`` (within ``box``) to ``thinner``."""
    src, mode, note = filtered(src, crs, options)
    return src, loader(src, to_local, mode, None, thinner, check, box, box is NOTHING, exclude=options.exclude), note


def _pad(lo: np.ndarray, hi: np.ndarray) -> float:
    """Margin (m) around a box from header bounds: reprojected corners may not enclose every point."""
    return 1.0 + 0.02 * float(np.max(hi[:2] - lo[:2]))


def _all_points(src: Source, to_local):
    """Every point of ``src`` (all classes), chunk by chunk in the local frame, with its class."""
    return lambda: ((to_local(xyz), cls) for xyz, cls in src.chunks())


def _describe(src: Source, crs: pyproj.CRS, loaded: Loaded, note: str) -> dict:
    """report.json's description of an input: what was read of ``src`` and kept of it (``loaded``)."""
    return {
        "soil_rule": (loaded.nonsoil.rule if loaded.nonsoil is not None else PointRule()).describe(),
        "path": src.path,
        "points": int(src.count),
        "points_used": loaded.used,
        "points_after_crop": loaded.extra["cropped"],
        "selection": note,
        "crs": crs.name,
        "crs_wkt": crs.to_wkt(),
    }


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
