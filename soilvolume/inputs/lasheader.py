"""Sanity of a LAS/LAZ header before any reader trusts it, checked against the file size with plain
``struct`` reads in a bounded number of steps (signature, version, header size, point data offset,
each (E)VLR within bounds, point format and record length, point count, finite non-zero scales,
finite offsets and bounds); readers also check the points they decode (:class:`BoundsCheck`)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from ..core.types import SoilVolumeError

VLR_HEADER, EVLR_HEADER = 54, 60
#: smallest point record of each point data format (LAS 1.4, Table 7 and following)
MIN_RECORD = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
MIN_HEADER = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
#: a compressed point record is never smaller than this many bytes, on average
MIN_LAZ_BYTES_PER_POINT = 0.01
#: how far inside a header bound the outermost point may lie, as a fraction of the extent
LOOSE = 0.005


def _fail(path: Path, problem: str) -> SoilVolumeError:
    return SoilVolumeError(f"{path}: corrupt LAS header ({problem})")


def check_las_header(path: Path) -> None:
    """Raise naming the file when its header is inconsistent."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(375)
        if len(head) < 227 or head[:4] != b"LASF":
            raise SoilVolumeError(f"{path}: not a readable LAS/LAZ file (no LASF signature, or too short)")
        major, minor = head[24], head[25]
        if major != 1 or minor not in MIN_HEADER:
            raise _fail(path, f"version {major}.{minor}")
        header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
        if not MIN_HEADER[minor] <= header_size <= offset <= size:
            raise _fail(path, f"header size {header_size} / point data offset {offset} for a {size}-byte file")
        _walk_records(fh, path, header_size, n_vlrs, offset, "VLR", ("in", "into"), "the point data")
        evlr_start, n_evlrs = struct.unpack_from("<QI", head, 235) if minor >= 4 else (0, 0)
        if n_evlrs and not offset <= evlr_start <= size:
            raise _fail(path, f"{n_evlrs} EVLRs declared at byte {evlr_start} of a {size}-byte file")
        _walk_records(fh, path, evlr_start, n_evlrs, size, "EVLR", ("past", "past"), "the end of the file")
    fmt_byte, rec_len = struct.unpack_from("<BH", head, 104)
    fmt, compressed = fmt_byte & 0x3F, bool(fmt_byte & 0xC0)
    if fmt not in MIN_RECORD or rec_len < MIN_RECORD[fmt]:
        raise _fail(path, f"point format {fmt} with {rec_len}-byte records")
    count = struct.unpack_from("<I", head, 107)[0]
    if minor >= 4:
        count = struct.unpack_from("<Q", head, 247)[0] or count
    by_return = sum(struct.unpack_from("<15Q", head, 255)) if minor >= 4 else 0
    by_return = by_return or sum(struct.unpack_from("<5I", head, 111))
    if by_return > count:
        raise _fail(path, f"{by_return} points counted by return, the header says {count}")
    _check_numbers(path, struct.unpack_from("<12d", head, 131), count)
    compressed = compressed or path.suffix.lower() == ".laz"
    _check_count(path, count, rec_len, evlr_start if n_evlrs else size, offset, compressed)


def _walk_records(fh, path: Path, pos: int, count: int, end: int, kind: str, words: tuple, limit: str) -> None:
    """Step over ``count`` (E)VLRs from byte ``pos``, each to end by byte ``end`` (one step per record
    that fits, so an absurd count stops at the first that does not)."""
    header, length_format = (VLR_HEADER, "<H") if kind == "VLR" else (EVLR_HEADER, "<Q")
    for i in range(count):
        if pos + header > end:
            raise _fail(path, f"{count} {kind}s declared, {kind} {i + 1} would start {words[0]} {limit}")
        fh.seek(pos + 20)
        (length,) = struct.unpack(length_format, fh.read(struct.calcsize(length_format)))
        pos += header + length
        if pos > end:
            raise _fail(path, f"{kind} {i + 1} runs {words[1]} {limit}")


def _check_numbers(path: Path, values: tuple[float, ...], count: int) -> None:
    """Finite non-zero scales, finite offsets and bounds; with points, bounds in order and within
    what 32-bit integers store (offset +- scale * 2^31)."""
    scales, offsets, bounds = values[:3], values[3:6], values[6:]
    if not all(math.isfinite(s) and s != 0 for s in scales):
        raise _fail(path, f"scale factors {scales} must be finite and non-zero")
    if not all(math.isfinite(v) for v in offsets + bounds):
        raise _fail(path, "offsets and bounds must be finite numbers")
    if not count:
        return
    for axis, scale, offset, hi, lo in zip("xyz", scales, offsets, bounds[::2], bounds[1::2], strict=True):
        reach = abs(scale) * (2**31 + 1)
        if lo > hi or lo < offset - reach or hi > offset + reach:
            raise _fail(path, f"{axis} bounds {lo:g}..{hi:g} impossible with offset {offset:g} and scale {scale:g}")


def _check_count(path: Path, count: int, rec_len: int, end: int, offset: int, compressed: bool) -> None:
    """The point data, from ``offset`` to ``end``, holds ``count`` points (at least, compressed)."""
    data = end - offset
    if compressed:
        if count * MIN_LAZ_BYTES_PER_POINT > data + 1:
            raise _fail(path, f"{count} points cannot fit in {data} bytes of compressed data")
        return
    if count * rec_len > data:
        raise _fail(
            path,
            f"{count} points of {rec_len} bytes need {count * rec_len} bytes, "
            f"the file holds {data} (truncated file or wrong count)",
        )
    if data - count * rec_len >= rec_len:
        raise _fail(path, f"the file holds {data // rec_len} points, the header says {count}")


class BoundsCheck:
    """Decoded points against the header's bounds, chunk by chunk: none outside by more than a scale
    step, and together reaching each bound within :data:`LOOSE` of the extent (a corrupt scale or
    offset otherwise gives plausible-looking, wrongly scaled coordinates)."""

    def __init__(self, path: Path | str, header) -> None:
        self.path = path
        self.lo, self.hi = np.asarray(header.mins, float), np.asarray(header.maxs, float)
        self.tol = np.abs(np.asarray(header.scales, float)) + 1e-12 * np.maximum(abs(self.lo), abs(self.hi))
        self.seen_lo, self.seen_hi = np.full(3, np.inf), np.full(3, -np.inf)

    def extend(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Take in a chunk's per-axis min ``lo`` and max ``hi`` (an empty one's inf and -inf change nothing)."""
        if (lo < self.lo - self.tol).any() or (hi > self.hi + self.tol).any():
            raise SoilVolumeError(
                f"{self.path}: points lie outside the bounds in the LAS header (corrupt scale, offset or bounds)"
            )
        self.seen_lo, self.seen_hi = np.minimum(self.seen_lo, lo), np.maximum(self.seen_hi, hi)

    def finish(self) -> None:
        if not np.isfinite(self.seen_lo).all():
            return
        slack = 2 * self.tol + LOOSE * (self.hi - self.lo)
        if (self.seen_lo - self.lo > slack).any() or (self.hi - self.seen_hi > slack).any():
            raise SoilVolumeError(
                f"{self.path}: the points do not reach the bounds in the LAS header (corrupt scale, offset or bounds)"
            )


def creation_date(path: Path) -> str | None:
    """The survey date of a LAS/LAZ/COPC file, ``YYYY-MM-DD``, from its header's creation day of year
    and year (bytes 90-93); None for other formats, zeros, or a day the year lacks (366 of 2023)."""
    import calendar
    import datetime as dt

    try:
        with open(path, "rb") as fh:
            head = fh.read(94)
    except OSError:
        return None
    if len(head) < 94 or head[:4] != b"LASF":
        return None
    day, year = struct.unpack_from("<HH", head, 90)
    if not (1900 <= year <= 9999 and 1 <= day <= 365 + calendar.isleap(year)):
        return None
    return (dt.date(year, 1, 1) + dt.timedelta(days=day - 1)).isoformat()
