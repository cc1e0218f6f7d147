"""Streaming input: a cloud read chunk by chunk into the working frame, only the points later steps
need kept (float32, local) and the thinned registration subset built on the way: memory bounded by
the kept points. A source is a LAS/LAZ/COPC file or a ``.vpc`` of them (with a ``region``, only the
tiles and COPC nodes meeting it); other files and pipeline outputs arrive whole, as one chunk."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from .. import native
from ..core.cells import bounds
from ..core.types import SoilVolumeError
from ..soil.points import NonSoil, PointRule, Signals, decide, deciding_dims
from .chunkwork import Growing, NativeChunks, consume, native_work, numpy_work
from .io import GROUND, LAS_SUFFIXES, RawPoints, _check_readable, read_points, validate
from .lasread import file_chunks, is_copc, las_header, las_ranges
from .records import first_chunk_signals, las_records
from .thinning import MAX_COLUMNS, ColumnThinner  # noqa: F401  (their home was this module)
from .vpc import Vpc, read_vpc

CHUNK = 1_000_000


@dataclass
class Source:
    """A cloud to stream: its CRS, point count and bounds (file CRS and units), and its chunks."""

    path: str
    crs_wkt: str | None
    count: int
    lo: np.ndarray
    hi: np.ndarray
    has_class: bool
    raw: RawPoints | None = None  # whole cloud already in memory (non-LAS, pipeline output)
    vpc: Vpc | None = None  # a virtual point cloud: its tiles
    region: tuple[np.ndarray, np.ndarray] | None = None  # x/y box (file CRS) that reads may stop at
    index: tuple | None = None  # of a single file: (start, count, x/y lo, x/y hi) of each chunk read
    compressed: bool = False  # a LAZ file's points

    def chunks(self, size: int | None = None, signals: bool | Callable = False, origin=None) -> Iterator[tuple]:
        """(absolute xyz float64, classification or None[, signals]) per chunk (``records.las_chunks``);
        with a ``region``, chunks may hold points outside it; with ``origin``, xyz minus it."""
        if self.raw is not None:
            raw = self.raw
            xyz = raw.xyz if origin is None else raw.xyz - origin
            yield (xyz, raw.classification, raw.signals) if signals else (xyz, raw.classification)
            return
        if self.index is not None and self.region is not None and not is_copc(self.path):
            lo, hi = self.region  # the (start, count) of the indexed chunks whose x/y box meets it
            ranges = [(s, n) for s, n, a, b in self.index if (a <= hi).all() and (lo <= b).all()]
            yield from las_ranges(self.path, ranges, size or CHUNK, signals, origin)
            return
        for path in self.tiles():
            yield from file_chunks(path, self.region, size or CHUNK, signals=signals, origin=origin)

    def records(self, signals: bool | Callable = False, direct=None, whole_first: bool = False) -> Iterator[tuple]:
        """The undecoded chunks of the source's LAS/LAZ files (:func:`records.las_records`): the
        native kernel's input (:func:`native_reads` says when a source can)."""
        for path in self.tiles():
            count = _header(Path(path)).count
            yield from las_records(Path(path), count, CHUNK, signals, direct=direct, whole_first=whole_first)
            whole_first = whole_first and not count

    def within(self, lo, hi) -> Source:
        """This source, read only where it can meet the x/y box lo..hi (file CRS)."""
        return replace(self, region=(np.asarray(lo[:2], float), np.asarray(hi[:2], float)))

    def tiles(self) -> list[str]:
        """The files that a read of this source opens: of a VPC, the tiles whose x/y box meets the region."""
        if self.vpc is None:
            return [self.path]
        if self.region is None:
            return [t.path for t in self.vpc.tiles]
        lo, hi = self.region
        return [t.path for t in self.vpc.tiles if (np.less_equal(t.lo[:2], hi) & np.less_equal(lo, t.hi[:2])).all()]

    def materialize(self) -> RawPoints:
        """The whole cloud in memory (for steps that need all points at once, e.g. SMRF)."""
        if self.raw is not None:
            return self.raw
        xyz, cls, sig = zip(*self.chunks(signals=True), strict=True)
        cls = None if cls[0] is None else np.concatenate(cls)
        return RawPoints(np.concatenate(xyz), cls, self.crs_wkt, self.path, Signals.join(sig))


def open_source(path) -> Source:
    """A streamable LAS/LAZ/COPC file or VPC from its header(s), else the whole cloud read now. A VPC: its
    CRS (else its tiles'), bounds and count from the tiles' headers (checked finite by ``check_las_header``)."""
    p = Path(path)
    if p.suffix.lower() == ".vpc":
        vpc = read_vpc(p)
        first = _header(Path(vpc.tiles[0].path))
        if vpc.count == 0:
            raise SoilVolumeError(f"{p}: the point cloud is empty (0 points in {len(vpc.tiles)} tiles)")
        lo, hi = np.min([t.lo for t in vpc.tiles], axis=0), np.max([t.hi for t in vpc.tiles], axis=0)
        return Source(str(p), vpc.crs_wkt or first.crs_wkt, vpc.count, lo, hi, first.has_class, vpc=vpc)
    _check_readable(p)
    if p.suffix.lower() not in LAS_SUFFIXES:
        return from_raw(read_points(p))
    src = _header(p)
    if src.count == 0:
        raise SoilVolumeError(f"{p}: the point cloud is empty (0 points)")
    return src


def _header(p: Path) -> Source:
    """A LAS/LAZ/COPC file's source from its header."""
    wkt, count, lo, hi, has_class, compressed = las_header(p)
    return Source(str(p), wkt, count, lo, hi, has_class, compressed=compressed)


def from_raw(raw: RawPoints) -> Source:
    validate(raw)
    lo, hi = raw.xyz.min(axis=0), raw.xyz.max(axis=0)
    return Source(raw.path, raw.crs_wkt, len(raw.xyz), lo, hi, raw.classification is not None, raw)


@dataclass
class Loaded:
    """One epoch streamed: kept soil points (float32), the thinned subset, counts, and the points its
    rule says are not soil within the same box."""

    xyz: np.ndarray
    thin: np.ndarray
    points: int = 0
    used: int = 0
    note: str = ""
    extra: dict = field(default_factory=dict)
    nonsoil: NonSoil | None = None


def epoch_rule(src: Source, cls: np.ndarray | None, sig, mode: str, exclude: str) -> PointRule:
    """The epoch's point rule from its first chunk (:func:`soil.points.decide`), keeping class 2
    only for ``class`` (an error without any) or ``auto`` when the chunk has some."""
    has = cls is not None and bool((cls == GROUND).any())
    if mode == "class" and not has:
        raise SoilVolumeError(f"{src.path}: {{opt:ground=class}} needs ground (class 2) points; the file has none")
    return replace(decide(cls, sig, mode, exclude), use_class=mode == "class" or (mode == "auto" and has))


def _labelled(
    src: Source, to_local, boxes: bool, mode: str, exclude: str, keep: Callable | None = None
) -> tuple[Iterator[tuple], Callable, bool]:
    """(chunks as (points, labels, rule, x/y box when ``boxes``, ``keep`` of the points or None),
    the conversion to local still to apply, whether the chunks are undecoded records for the native
    kernel). The rule is decided on the first chunk (read whole beforehand for the kernel's smaller
    pieces); only the signals it uses are read. Without the kernel a plain ``Shift`` is subtracted
    in the decoding, and ``keep`` applied there too."""
    by_kernel = native_reads(src, to_local, keep)
    fused = src.raw is None and not boxes and hasattr(to_local, "inplace")
    early = keep if fused and not by_kernel else None
    shift = (lambda xyz: xyz) if fused else to_local if src.raw is not None else getattr(to_local, "inplace", to_local)
    rule: PointRule | None = None
    first = next((h for h in map(_header, map(Path, src.tiles())) if h.count), None) if by_kernel else None
    ahead = first is not None and not first.compressed  # the rule decided before the reading (first file with points)
    if ahead:  # on the first chunk as a whole, as numpy decides it (the kernel gets pieces)
        cls, sig = first_chunk_signals(Path(first.path), first.count, CHUNK, lambda c: deciding_dims(c, mode, exclude))
        rule = epoch_rule(src, cls, sig, mode, exclude)

    def wanted(cls) -> set[str]:
        return deciding_dims(cls, mode, exclude) if rule is None else rule.signal_dims

    def direct(has_class: bool):  # a chunk left in the file once its labels need no signal
        return False if rule is None or not whole_files else rule.class_table(has_class)

    whole_files = by_kernel and file_kernel()

    def run() -> Iterator[tuple]:
        nonlocal rule
        if by_kernel:  # a LAZ file's first chunk in one piece, the rule decided on it (once decompressed)
            chunks = src.records(signals=wanted, direct=direct, whole_first=not ahead)
        else:
            chunks = src.chunks(signals=wanted, origin=to_local.origin if fused else None)
        for xyz, cls, sig in chunks:
            if rule is None:
                rule = epoch_rule(src, cls, sig, mode, exclude)
            inside = None if early is None else early(xyz)
            item = xyz, rule.labels(cls, sig), rule, bounds(xyz, 2) if boxes and not by_kernel else None, inside
            del xyz, cls, sig, inside  # held by the item only
            yield item

    return run(), shift, by_kernel


def file_kernel() -> bool:
    """Whether the native library reads whole chunks from files itself (POSIX builds)."""
    return hasattr(native.kernels(), "sv_file_chunk")  # None without the library


def native_reads(src: Source, to_local, keep: Callable | None) -> bool:
    """Whether ``src`` streams through the native chunk kernel: the library is there, whole LAS/LAZ
    files (no COPC nodes or indexed ranges), a plain shift and a rasterized crop polygon (or none)."""
    if native.kernels() is None or src.raw is not None or not hasattr(to_local, "inplace"):
        return False
    if keep is not None and not hasattr(keep, "framed"):
        return False
    return src.region is None or (src.index is None and not any(is_copc(t) for t in src.tiles()))


def load(
    src: Source,
    to_local: Callable[[np.ndarray], np.ndarray],
    mode: str,
    keep: Callable[[np.ndarray], np.ndarray] | None,
    thinner: ColumnThinner,
    check: Callable[[], None] | None = None,
    box: tuple[np.ndarray, np.ndarray] | None = None,
    indexed: bool = False,
    exclude: str = "auto",
) -> Loaded:
    """Stream ``src``: label its points (:func:`epoch_rule` of ``mode`` and ``exclude``), convert
    with ``to_local``, feed the soil points ``keep`` passes (all when None) to ``thinner`` and keep
    those within the x/y ``box`` (all when None) at full resolution, the non-soil ones beside them.
    ``indexed``: also record each chunk's x/y box (``extra["index"]``)."""
    out = Growing(src.count if box is None or (box[1] >= box[0]).all() else 0), Growing(0), Growing(0, None, np.uint8)
    index = [] if indexed and src.vpc is None and src.raw is None and not is_copc(src.path) else None
    chunks, shift, by_kernel = _labelled(src, to_local, index is not None, mode, exclude, keep)
    kernel = NativeChunks(native.kernels(), thinner, keep, box, to_local.origin, CHUNK) if by_kernel else None
    work = partial(native_work, kernel, out=out) if kernel else partial(numpy_work, shift, keep, thinner, box, out=out)
    try:
        points, used, cropped, reading, rule = consume(chunks, work, index, check)
    finally:
        if kernel:
            kernel.close()
    note = "class 2 (ground)" if rule is not None and rule.use_class else "all points"
    rule = rule or PointRule()
    thin, counts = thinner.columns()
    extra = {"read_s": reading, "cropped": cropped, "counts": counts, "index": None if index is None else tuple(index)}
    nonsoil = NonSoil(out[1].result(), out[2].result(), rule) if rule.active else None
    return Loaded(out[0].result(), thin, points, used, note, extra, nonsoil)
