"""Seeded bit flips in the header and VLRs of small LAS files: every outcome is a one-line
SoilVolumeError or a plausible result, never a traceback, a hang or a crash.

Plausible: the same number of points, each within 1 % of the cloud's extent of the original. A
flip in a scale factor's low bits moves points toward the offset; the reader refuses it once the
points miss a header bound by more than 0.5 % of the extent (``lasheader.LOOSE``), so smaller
deviations are all that can pass.
"""

from __future__ import annotations

import signal

import laspy
import numpy as np
import pyproj
import pytest

from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs.prepare import resolve_crs
from soilvolume.inputs.stream import open_source

CASES = {"1.4.las": 120, "1.2.las": 80, "1.4.laz": 80}  # 280 flips in all
TOLERANCE = 0.01  # of the extent


class _Timeout(Exception):
    pass


def _write(path, version: str, n: int = 300, seed: int = 0) -> np.ndarray:
    """A small cloud with a CRS VLR and complete header counts (points by return)."""
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=6 if version == "1.4" else 1, version=version)
    header.offsets, header.scales = [500000, 3900000, 0], [0.001] * 3
    header.add_crs(pyproj.CRS("EPSG:32654"))
    las = laspy.LasData(header)
    las.x = rng.uniform(0, 50, n) + 500000
    las.y = rng.uniform(0, 50, n) + 3900000
    las.z = rng.uniform(40, 60, n)
    las.classification = rng.integers(1, 3, n).astype(np.uint8)
    las.return_number = las.number_of_returns = np.ones(n, np.uint8)
    las.update_header()
    las.write(str(path), do_compress=path.suffix == ".laz")
    return np.c_[las.x, las.y, las.z]


def _read(path):
    src = open_source(path)
    resolve_crs(src, None, "--before-crs")
    return src.materialize().xyz


def _outcome(path, original: np.ndarray) -> str:
    signal.setitimer(signal.ITIMER_REAL, 10.0)
    try:
        xyz = _read(path)
    except SoilVolumeError as exc:
        assert len(str(exc).splitlines()) == 1 and str(path) in str(exc), str(exc)
        return "error"
    except _Timeout:
        pytest.fail(f"{path}: the reader hung")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    assert xyz.shape == original.shape, f"{path}: {len(xyz)} points read, {len(original)} written"
    deviation = float((np.abs(xyz - original) / np.ptp(original, axis=0)).max())
    assert deviation < TOLERANCE, f"{path}: points moved by {deviation:.2%} of the extent"
    return "same" if deviation == 0 else "close"


@pytest.fixture
def alarm():
    def fire(*_):
        raise _Timeout

    old = signal.signal(signal.SIGALRM, fire)
    yield
    signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize("kind", sorted(CASES))
def test_bit_flips_in_header_and_vlrs(tmp_path, alarm, kind):
    version, suffix = kind[:3], kind[3:]
    original_path = tmp_path / f"orig{suffix}"
    original = _write(original_path, version)
    data = original_path.read_bytes()
    end = laspy.read(original_path).header.offset_to_point_data  # header + VLRs
    rng = np.random.default_rng(11)
    seen: dict[str, int] = {}
    for case in range(CASES[kind]):
        flipped = bytearray(data)
        # half the flips in the fixed header (where the counts, scales and offsets are)
        at = int(rng.integers(0, 375 if case % 2 else end))
        flipped[at] ^= 1 << int(rng.integers(0, 8))
        path = tmp_path / f"flip{case}_byte{at}{suffix}"
        path.write_bytes(bytes(flipped))
        kind = _outcome(path, original)
        seen[kind] = seen.get(kind, 0) + 1
        path.unlink()
    assert seen.get("error", 0) > 10 and seen.get("same", 0) > 10, seen
