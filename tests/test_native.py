"""The native kernels (soilvolume/native/*.c) give the bits of their numpy twins: the chunk
kernel of the streaming against :func:`soilvolume.inputs.chunkwork.numpy_chunk`, the column means
of the registration against numpy's bincounts, and a whole estimate with and without the library;
the library is built from this source (its name carries the source's digest) or not used."""

from __future__ import annotations

import os
import subprocess
import sys

import laspy
import numpy as np
import pytest

from soilvolume import native
from soilvolume.inputs import chunkwork
from soilvolume.inputs.chunkwork import Growing, NativeChunks, numpy_chunk
from soilvolume.inputs.footprint import PolygonMask
from soilvolume.inputs.lasheader import BoundsCheck
from soilvolume.inputs.records import Records, chunk_pieces
from soilvolume.inputs.thinning import ColumnThinner
from soilvolume.native import OFF_THE_GIL


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    """The kernels built now from this source into a folder of the test's (the checkout's own
    build is not assumed)."""
    out = tmp_path_factory.mktemp("native")
    done = subprocess.run(
        [sys.executable, "-m", "soilvolume.native.build", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    if done.returncode != 0:
        pytest.skip(f"no C compiler here: {done.stderr.strip()}")
    old = os.environ.get(native.DIR_ENV)
    os.environ[native.DIR_ENV] = str(out)
    native.reset()
    yield native.kernels()
    if old is None:
        os.environ.pop(native.DIR_ENV)
    else:
        os.environ[native.DIR_ENV] = old
    native.reset()


def _records(rng, n: int, point_format: int) -> Records:
    """``n`` random point records of a LAS point format, with the header values of a real file."""
    fmt = laspy.PointFormat(point_format)
    array = np.zeros(n, fmt.dtype())
    for k, span in zip("XYZ", (60_000, 40_000, 3_000), strict=True):
        array[k] = rng.integers(-span, span, n)
    header = laspy.LasHeader(point_format=point_format, version="1.4")
    header.scales, header.offsets = np.array([0.001, 0.001, 0.0025]), np.array([500_012.0, 3_900_007.0, 41.0])
    header.mins, header.maxs = np.full(3, -1e12), np.full(3, 1e12)
    return Records(array, header.scales, header.offsets, BoundsCheck("x.las", header), True)


def _piece(rec: Records, a: int, b: int, flush: bool) -> Records:
    return Records(rec.array[a:b], rec.scales, rec.offsets, rec.check, True, flush)


def _chunks(rec: Records, rng) -> list[list[Records]]:
    """The records as two chunks, the first in up to three pieces (the last ending the chunk)."""
    n = len(rec)
    if n < 4:
        return [[rec]]
    c = int(rng.integers(2, n - 1))
    edges = [0, *sorted(set(rng.integers(1, c, 2).tolist())), c]
    first = [_piece(rec, a, b, b == c) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return [first, [_piece(rec, c, n, True)]]


def _streamed(lib, chunks: list[list[Records]], labels, origin, polygon, box, lattice):
    """Each chunk's pieces through the kernel (``lib``) or each whole chunk through numpy (None)."""
    thinner = ColumnThinner(*lattice)
    out = Growing(0), Growing(0), Growing(0, None, np.uint8)
    counts = []
    kernel = None if lib is None else NativeChunks(lib, thinner, polygon, box, origin, 10_000)
    start = 0
    for parts in chunks:
        n = sum(len(p) for p in parts)
        if kernel is None:
            whole = Records(np.concatenate([p.array for p in parts]), parts[0].scales, parts[0].offsets, None, True)
            lab = None if labels is None else labels[start : start + n]
            got = [numpy_chunk(whole, lab, origin, polygon, thinner, box, *out)]
        else:
            got, at = [], start
            for p in parts:
                got.append(kernel.add(p, None if labels is None else labels[at : at + len(p)], *out))
                at += len(p)
        counts.append(
            (
                sum(g.cropped for g in got),
                sum(g.soil for g in got),
                np.min([g.lo for g in got], axis=0).tobytes(),
                np.max([g.hi for g in got], axis=0).tobytes(),
            )
        )
        start += n
    return counts, thinner.sums.tobytes(), thinner.columns()[0].tobytes(), [o.result().tobytes() for o in out]


@pytest.mark.parametrize("case", range(12))
def test_the_chunk_kernel_gives_the_numpy_bits(lib, case):
    """Decoding, crop, labels, thinning and the kept points of the kernel, fed in pieces, equal
    numpy's on whole chunks bit for bit: with and without labels, crop polygon and box (also an
    empty box), on lattices the points overflow, over several chunks sharing columns."""
    rng = np.random.default_rng(case)
    rec = _records(rng, int(rng.integers(1, 6_000)), (6, 1, 3, 7)[case % 4])
    labels = None if case % 3 == 0 else rng.choice(np.array([0, 0, 0, 1, 2, 3], np.uint8), len(rec))
    origin = np.array([500_010.0, 3_900_004.0, 40.0]) + rng.normal(0, 3, 3)
    poly = rng.normal(0, 25, (12, 2)) if case % 2 else None
    polygon = None if poly is None else PolygonMask(poly, resolution=rng.uniform(0.3, 2.0))
    box = [None, (np.array([-20.0, -15.0]), np.array([25.0, 30.0])), (np.full(2, np.inf), np.full(2, -np.inf))][
        case % 3
    ]
    lattice = (rng.normal(0, 10, 2) - 40, rng.normal(0, 10, 2) + 40, rng.uniform(0.2, 3.0))
    chunks = _chunks(rec, rng)
    a = _streamed(lib, chunks, labels, origin, polygon, box, lattice)
    b = _streamed(None, chunks, labels, origin, polygon, box, lattice)
    assert a == b
    assert a[0][0][0] > 0 or polygon is not None or case % 3 == 2  # something was kept


def test_pieces_never_straddle_chunks():
    def pieces(count, size, piece):
        return [m for chunk in chunk_pieces(count, size, piece) for m in chunk]

    assert chunk_pieces(10, 4, 3) == [[3, 1], [3, 1], [2]]
    assert pieces(10, 4, 3) == [3, 1, 3, 1, 2]
    assert pieces(8, 4, 4) == [4, 4]
    assert pieces(0, 4, 3) == []
    lengths = pieces(2_489_649, 1_000_000, 125_000)
    assert sum(lengths) == 2_489_649 and max(lengths) == 125_000 and np.cumsum(lengths)[7] == 1_000_000


@pytest.mark.parametrize("transposed", [False, True])
def test_the_columns_kernel_gives_the_numpy_bits(lib, transposed, monkeypatch):
    """The registration's column means (points off the grid, NaN, a transposed view)."""
    from soilvolume.registration import columns

    rng = np.random.default_rng(7)
    for _ in range(60):
        n = int(rng.integers(1, 4_000))
        xyz = rng.normal(0, 10, (n, 3))
        xyz[rng.integers(0, n, 3)] = np.nan
        if transposed:
            xyz = np.ascontiguousarray(xyz.T).T
        lo, cell = rng.normal(0, 5, 2), rng.uniform(0.1, 3)
        shape = (int(rng.integers(1, 60)), int(rng.integers(1, 60)))
        a = columns._binned(xyz, lo, cell, shape)
        monkeypatch.setenv(native.ENV, "0")
        native.reset()
        b = columns._binned(xyz, lo, cell, shape)
        monkeypatch.delenv(native.ENV)
        native.reset()
        assert a.xyz.tobytes() == b.xyz.tobytes() and np.array_equal(a.row, b.row) and np.array_equal(a.col, b.col)


def test_a_library_of_other_source_is_not_loaded(tmp_path, monkeypatch):
    """Only a build of this very source is loaded: a file with another digest in its name, or a
    library that is not one, leaves the numpy path on."""
    name = native.library_name()
    other = name.replace(name.split("-")[1], "0" * 16)
    (tmp_path / other).write_bytes(b"not a library")
    monkeypatch.setenv(native.DIR_ENV, str(tmp_path))
    monkeypatch.setattr(native, "HERE", tmp_path)
    native.reset()
    assert native.kernels() is None
    (tmp_path / name).write_bytes(b"not a library either")
    native.reset()
    assert native.kernels() is None
    native.reset()


def test_without_a_build_the_numpy_path_runs_nothing_is_compiled_and_only_debug_says_so(tmp_path, monkeypatch, capsys):
    """No library of this source: no compiler is run (the kernels are built at install, never
    during a run), the numpy path runs, and the line saying so appears under SOILVOLUME_DEBUG only."""
    monkeypatch.setenv(native.DIR_ENV, str(tmp_path))
    monkeypatch.setattr(native, "HERE", tmp_path)
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: pytest.fail("a compiler was run"))
    for debug, said in (("", ""), ("1", f"soilvolume: no {native.library_name()}")):
        monkeypatch.setenv("SOILVOLUME_DEBUG", debug)
        native.reset()
        assert native.kernels() is None
        err = capsys.readouterr().err
        assert (err.startswith(said) if said else err == "") and list(tmp_path.iterdir()) == []
    native.reset()


def test_a_run_gives_the_same_outputs_with_and_without_the_kernels(lib, misaligned_pair, tmp_path):
    """A whole estimate: every raster and the change areas byte for byte, and the volumes."""
    before, after, _ = misaligned_pair
    outs = {}
    for flag in ("1", "0"):
        out = tmp_path / f"native-{flag}"
        env = {**os.environ, native.ENV: flag}
        done = subprocess.run(
            [sys.executable, "-m", "soilvolume", "estimate", str(before), str(after), "--out", str(out), "--quiet"],
            capture_output=True,
            text=True,
            timeout=600,
            env=env,
        )
        assert done.returncode == 0, done.stderr
        outs[flag] = out
    files = sorted(p.name for p in outs["1"].iterdir() if p.suffix in (".tif", ".geojson"))
    assert len(files) >= 6
    for name in files:
        assert (outs["1"] / name).read_bytes() == (outs["0"] / name).read_bytes(), name


def test_no_compiler_builds_nothing_and_says_so(tmp_path):
    from soilvolume.native.build import build, main

    path, note = build(tmp_path, cc="no-such-compiler")
    assert path is None and "no C compiler" in note and not list(tmp_path.iterdir())
    assert main(["--out", str(tmp_path), "--cc", "no-such-compiler", "--quiet"]) == 1


def test_the_build_names_its_source_and_platform():
    name = native.library_name()
    assert name.startswith("_soilvolume_kernels-") and native.tag() in name
    assert [p.name for p in native.SOURCES] == ["kernels.h", "chunks.c", "cells.c", "registration.c"]


def _both(monkeypatch, fn):
    """``fn()`` with the kernels, then without."""
    a = fn()
    monkeypatch.setenv(native.ENV, "0")
    native.reset()
    b = fn()
    monkeypatch.delenv(native.ENV)
    native.reset()
    return a, b


@pytest.mark.parametrize("layout", ["rows", "transposed"])
def test_the_grid_kernels_give_the_numpy_bits(lib, monkeypatch, layout):
    """An epoch's DEM (cells, heights, offsets, the sorted keys' statistics) from float32 points
    with and without the kernels: points off the grid, several blocks, moved by a transform."""
    from soilvolume.dem import cellstats
    from soilvolume.dem import grid as gridmod
    from soilvolume.registration.rigid import transform_points32

    rng = np.random.default_rng(3)
    xyz = np.c_[rng.uniform(-5, 65, 30_000), rng.uniform(-5, 45, 30_000), rng.normal(2, 0.3, 30_000)].astype(np.float32)
    grid = gridmod.make_grid(np.array([0.0, 0.0]), np.array([60.0, 40.0]), 0.7, np.zeros(3), None)
    monkeypatch.setattr(cellstats, "BLOCK", 7_000)
    t = np.eye(4)
    t[:3, 3] = [0.4, -0.2, 0.05]
    move = None if layout == "rows" else (lambda p: transform_points32(p, t))
    a, b = _both(monkeypatch, lambda: gridmod.epoch_dem(xyz, grid, "robust-mean", move=move))
    assert np.isfinite(a.heights).sum() > 1_000
    for name in ("heights", "counts", "spread", "skew", "dx", "dy"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name


@pytest.mark.parametrize("spread", [0.002, 0.5, 3.0, 1_000.0])
def test_the_sorted_keys_are_numpys(lib, monkeypatch, spread):
    """Cells of a few keys (sorted by comparisons) and of many (by their bytes: one, two or three
    passes for a cell's heights within 2.5 cm, 6.5 m, 1.6 km; by comparisons beyond), ties too."""
    from soilvolume.dem.cellstats import _SortedCells

    rng = np.random.default_rng(4)
    for n_cells, n in ((1, 5), (7, 400), (3_000, 90_000), (40, 200_000)):
        ids = rng.integers(0, n_cells, n)
        z = np.round(rng.normal(10, spread, n), 4)
        a, b = _both(monkeypatch, lambda: _SortedCells(ids.copy(), z.copy(), n_cells, own=True))  # noqa: B023
        assert np.array_equal(a.key, b.key) and np.array_equal(a.counts, b.counts)
        assert a.quantile(0.5).tobytes() == b.quantile(0.5).tobytes()


@pytest.mark.parametrize("point_format", [1, 6])
@pytest.mark.parametrize("classified", [True, False])
def test_whole_chunks_read_by_the_kernel_load_what_numpy_loads(lib, tmp_path, monkeypatch, point_format, classified):
    """A LAS file streamed with its later chunks left to the kernel to read (``sv_file_chunk``,
    labels from the classification byte) loads what the numpy path loads, bit for bit."""
    from soilvolume.inputs import stream
    from soilvolume.inputs.crs import Shift
    from soilvolume.inputs.records import class_byte

    rng = np.random.default_rng(point_format)
    n = 9_000
    las = laspy.LasData(laspy.LasHeader(point_format=point_format, version="1.4"))
    las.header.scales, las.header.offsets = np.full(3, 0.001), np.array([500_000.0, 3_900_000.0, 0.0])
    las.x, las.y, las.z = 500_000 + rng.uniform(0, 60, n), 3_900_000 + rng.uniform(0, 40, n), 50 + rng.normal(0, 0.2, n)
    if classified:
        las.classification = rng.choice(np.array([2, 2, 2, 5, 6, 7], np.uint8), n)
        las.synthetic = rng.random(n) < 0.3  # a flag bit beside the class (formats 0-5: the same byte)
    path = tmp_path / "c.las"
    las.write(str(path))
    at, mask = class_byte(las.points.array.dtype)
    assert np.array_equal(las.points.array.view(np.uint8).reshape(n, -1)[:, at] & mask, np.asarray(las.classification))
    monkeypatch.setattr(stream, "CHUNK", 2_000)  # five chunks, all read by the kernel
    src = stream.open_source(path)
    keep = PolygonMask(np.array([[-5.0, -5.0], [45.0, -5.0], [20.0, 25.0]]))
    box = np.array([-11.0, -11.0]), np.array([60.0, 40.0])

    def run():
        got = stream.load(src, Shift(np.array([500_010.0, 3_900_010.0, 49.0])), "auto", keep, ColumnThinner(*box, 0.5))
        ns = (got.nonsoil.xyz.tobytes(), got.nonsoil.labels.tobytes()) if got.nonsoil else None
        return got.xyz.tobytes(), got.thin.tobytes(), got.used, got.extra["cropped"], ns

    calls, gate = [], []
    monkeypatch.setattr(
        NativeChunks, "_from_file", lambda self, rec, f=NativeChunks._from_file: calls.append(1) or f(self, rec)
    )
    monkeypatch.setattr(chunkwork, "address", lambda a, f=chunkwork.address: gate.append(OFF_THE_GIL.is_set()) or f(a))
    a, b = _both(monkeypatch, run)
    assert a == b and len(calls) == 5  # every chunk, the first too (its rule decided beforehand)
    assert (a[2] < n) == classified and (a[4] is not None) == classified
    assert any(gate) and not OFF_THE_GIL.is_set()  # said while the kernel reads a file, and only then


def test_the_icp_kernels_give_the_numpy_bits(lib, monkeypatch):
    """Point-to-plane ICP with its kept neighbours proven (and swapped with the search before) and
    its step terms by the kernels: the same poses, fitness, RMSE and iterations as numpy."""
    from soilvolume.registration import icp
    from soilvolume.registration.rigid import transform_points

    rng = np.random.default_rng(11)
    gx, gy = np.meshgrid(np.arange(0, 60, 0.5), np.arange(0, 40, 0.5))
    h = 0.4 * np.sin(gx / 7) + 0.3 * np.cos(gy / 5)
    tgt = np.c_[gx.ravel(), gy.ravel(), h.ravel()]
    normals = np.c_[-0.4 / 7 * np.cos(gx / 7).ravel(), 0.3 / 5 * np.sin(gy / 5).ravel(), np.ones(gx.size)]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    pick = rng.choice(len(tgt), 3_000, replace=False)
    src = tgt[pick] + rng.normal(0, 0.02, (3_000, 3))
    for shift, dist, k in (((0.3, -0.2, 0.05), 1.5, 0.5), ((0.05, 0.02, 0.0), 0.4, 0.15), ((1.0, 0.5, 0.1), 3.0, 1.0)):
        t = np.eye(4)
        t[:3, 3] = shift
        moved = transform_points(src, t)
        a, b = _both(monkeypatch, lambda: icp.point_to_plane(moved, tgt, normals, dist, np.eye(4), k))  # noqa: B023
        assert a.transform.tobytes() == b.transform.tobytes()
        assert (a.fitness, a.inlier_rmse, a.iterations) == (b.fitness, b.inlier_rmse, b.iterations)
        assert a.iterations > 2


@pytest.mark.parametrize("suffix", [".las", ".laz"])
@pytest.mark.parametrize("kind", ["class", "colour"])
def test_the_rule_is_decided_on_the_first_chunk_not_its_first_piece(lib, tmp_path, monkeypatch, kind, suffix):
    """The kernel gets a chunk in pieces; the epoch's rule is still decided on the whole first
    chunk, as numpy decides it: ground points only after the first piece still make the rule
    select class 2, and a colour threshold comes from the whole chunk's colours."""
    from soilvolume.inputs import records, stream
    from soilvolume.inputs.crs import Shift

    rng = np.random.default_rng(9)
    n = 12_000
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales, las.header.offsets = np.full(3, 0.001), np.array([500_000.0, 3_900_000.0, 0.0])
    las.x, las.y, las.z = 500_000 + rng.uniform(0, 60, n), 3_900_000 + rng.uniform(0, 40, n), 50 + rng.normal(0, 0.2, n)
    if kind == "class":
        las.classification = np.where(np.arange(n) < 1_500, 1, 2).astype(np.uint8)  # no ground in the first piece
    else:
        green = (np.arange(n) >= 1_500) & (rng.random(n) < 0.4)  # no vegetation in the first piece
        las.red = np.where(green, 20_000, 40_000).astype(np.uint16)
        las.green = np.where(green, 50_000, 38_000).astype(np.uint16)
        las.blue = np.where(green, 15_000, 36_000).astype(np.uint16)
    path = tmp_path / f"late{suffix}"
    las.write(str(path), do_compress=suffix == ".laz")
    monkeypatch.setattr(stream, "CHUNK", 6_000)
    monkeypatch.setattr(records, "PIECE", 1_000)
    src = stream.open_source(path)
    box = np.array([-11.0, -11.0]), np.array([60.0, 40.0])

    def run():
        got = stream.load(src, Shift(np.array([500_010.0, 3_900_010.0, 49.0])), "auto", None, ColumnThinner(*box, 0.5))
        rule = got.nonsoil.rule if got.nonsoil is not None else None
        return rule, got.used, got.xyz.tobytes(), got.thin.tobytes()

    a, b = _both(monkeypatch, run)
    assert a == b
    assert (a[0].use_class if kind == "class" else a[0].green is not None) and a[1] < n


def test_the_centroids_kernel_gives_the_numpy_bits(lib, monkeypatch):
    rng = np.random.default_rng(12)
    t = ColumnThinner(np.array([-3.0, -2.0]), np.array([40.0, 30.0]), 0.7)
    t.add(rng.uniform(-5, 45, (20_000, 3)))
    t.add(rng.uniform(0, 10, (3_000, 3)))
    a, b = _both(monkeypatch, lambda: tuple(x.tobytes() for x in t.columns()))
    assert a == b and len(t.columns()[0]) > 1_000


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts the process's page faults (Linux)")
def test_the_thinning_writes_a_fresh_column_before_reading_it(lib):
    """A column's first point is written onto its zero sums, not added to them: a read of a page
    never written maps the shared zero page and the write after it faults again (and flushes
    the TLB of every core running the process). Sums on fresh pages fault about once a page."""
    import mmap
    import resource

    side = 1024  # columns a side: 4 x 8 MB of sums, 2048 pages each
    thinner = ColumnThinner(np.zeros(2), np.full(2, side - 1.0), 1.0)
    region = mmap.mmap(-1, thinner.sums.nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)  # never touched
    thinner.sums = np.frombuffer(region, np.float64).reshape(thinner.sums.shape)
    rec = _records(np.random.default_rng(3), 40_000, 1)
    rec.array["X"] = np.random.default_rng(4).integers(0, side * 1000, len(rec))  # 0.001 m: every column's row
    rec.array["Y"] = np.random.default_rng(5).integers(0, side * 1000, len(rec))
    origin = rec.offsets.copy()
    nothing = (np.full(2, np.inf), np.full(2, -np.inf))  # no points kept: only the sums are written
    kernel = NativeChunks(lib, thinner, None, nothing, origin, len(rec))
    out = Growing(0), Growing(0), Growing(0, None, np.uint8)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    kernel.add(rec, None, *out)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    pages = thinner.sums.nbytes // mmap.PAGESIZE
    assert int((thinner.sums[3] > 0).sum()) > 0.9 * 40_000 * np.exp(-40_000 / side**2)  # the points were added
    assert faults < 1.5 * pages, f"{faults} faults for {pages} pages of sums"


@pytest.mark.parametrize("keeping", [True, False])
@pytest.mark.parametrize("suffix", [".las", ".laz"])
@pytest.mark.parametrize("rule", ["class", "colour", "none"])
def test_a_tile_scanned_by_the_kernel_is_what_numpy_scans(lib, tmp_path, monkeypatch, suffix, rule, keeping):
    """The first pass's scan of a VPC tile on the kernel (``distributed.scan.native_scan``) gives numpy's
    thinning sums and counts bit for bit, and kept chunks of numpy's sizes whose soil points and
    other points (with their labels) are numpy's, each in order: what the grid takes apart."""
    from soilvolume.distributed import scan
    from soilvolume.inputs.crs import Shift
    from soilvolume.soil.points import PointRule

    rng = np.random.default_rng(7)
    n = 9_000
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales, las.header.offsets = np.full(3, 0.001), np.array([500_000.0, 3_900_000.0, 0.0])
    las.x, las.y, las.z = 500_000 + rng.uniform(0, 60, n), 3_900_000 + rng.uniform(0, 40, n), 50 + rng.normal(0, 0.2, n)
    las.classification = rng.choice(np.array([2, 2, 2, 5, 6, 7], np.uint8), n)
    las.red, las.green, las.blue = (rng.integers(0, 65535, n) for _ in range(3))
    path = tmp_path / f"t{suffix}"
    las.write(str(path))
    point_rule = {"class": PointRule(use_class=True), "colour": PointRule(green=0.05), "none": PointRule()}[rule]
    monkeypatch.setattr(scan, "CHUNK", 2_000)  # five chunks
    keep = PolygonMask(np.array([[-5.0, -5.0], [45.0, -5.0], [20.0, 25.0]]))
    thinning = (np.array([-11.0, -11.0]), np.array([60.0, 40.0]), 0.5, None)
    to_local = Shift(np.array([500_010.0, 3_900_010.0, 49.0]))

    run = _tile_scan(path, to_local, point_rule, keep, thinning, keeping)
    calls = []
    monkeypatch.setattr(scan, "NativeChunks", lambda *a, f=scan.NativeChunks: calls.append(1) or f(*a))
    (kind, *a), (numpy_kind, *b) = _both(monkeypatch, run)
    assert a == b and len(calls) == 1  # the kernel scanned it, then numpy
    assert (kind, numpy_kind) == ("Block", "tuple")  # the kernel's on the tile's columns only
    assert len(a[2]) == (5 if keeping else 0) and (a[0][1] < n) == (rule != "none")  # a rule left some points out


def _tile_scan(path, to_local, rule, keep, thinning: tuple, keeping: bool):
    """A function scanning the tile ``path`` as the first pass does: (the kind of its sums, its
    counts, the bytes of the epoch's thinning sums once its sums are added, the kept chunks'
    sizes, their soil points' bytes and their other points' and labels' bytes)."""
    from soilvolume.distributed import scan

    def run():
        kept = []
        got = scan.scan_unit(
            (str(path), None, None), None, to_local, rule, keep, thinning, False, None, kept if keeping else None
        )
        counts = tuple(got[k] for k in ("points", "used", "cropped"))
        epoch = ColumnThinner(*thinning)
        scan._add_in_order(epoch, {0: got["sums"]}, 0)
        sizes = [len(xyz) for xyz, _ in kept]
        soil = np.concatenate([xyz if lab is None else xyz[lab == 0] for xyz, lab in kept] or [np.empty(0)])
        other = [(xyz[lab != 0], lab[lab != 0]) for xyz, lab in kept if lab is not None]
        other = b"".join(x.tobytes() + la.tobytes() for x, la in other)
        return type(got["sums"]).__name__, counts, epoch.sums.tobytes(), sizes, soil.tobytes(), other

    return run


def test_a_tile_with_points_off_its_header_box_is_thinned_on_all_columns(lib, tmp_path, monkeypatch):
    """The kernel's scan thins a tile on the columns its header's box meets: a point that missed
    them (a box too small) makes it scan the tile again on all of them, and it gives numpy's bits."""
    from soilvolume.distributed import scan
    from soilvolume.inputs.crs import Shift
    from soilvolume.soil.points import PointRule

    rng = np.random.default_rng(8)
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.header.scales, las.header.offsets = np.full(3, 0.001), np.array([500_000.0, 3_900_000.0, 0.0])
    las.x, las.y, las.z = (
        500_000 + rng.uniform(0, 60, 5_000),
        3_900_000 + rng.uniform(0, 40, 5_000),
        rng.normal(0, 1, 5_000),
    )
    las.classification = np.full(5_000, 2, np.uint8)
    path = tmp_path / "t.las"
    las.write(str(path))
    thinning = (np.array([-20.0, -20.0]), np.array([70.0, 50.0]), 0.5, None)
    half = lambda thinning, box: (*thinning[:3], (box[0], (box[0] + box[1]) / 2))  # noqa: E731
    monkeypatch.setattr(scan, "narrowed", half)
    calls = []
    monkeypatch.setattr(scan, "NativeChunks", lambda *a, f=scan.NativeChunks: calls.append(1) or f(*a))
    run = _tile_scan(
        path, Shift(np.array([500_010.0, 3_900_010.0, 0.0])), PointRule(use_class=True), None, thinning, True
    )
    (kind, *a), (_, *b) = _both(monkeypatch, run)
    assert a == b and len(calls) == 2  # the kernel scanned it twice, then numpy
    assert kind == "tuple" and a[0][2] == 5_000  # every point cropped in and thinned


def test_an_empty_tile_is_left_to_the_numpy_scan(lib, tmp_path):
    """A VPC tile without points: the kernel's scan steps aside and the numpy scan finds nothing."""
    from soilvolume.distributed import scan
    from soilvolume.inputs.crs import Shift
    from soilvolume.soil.points import PointRule

    path = tmp_path / "empty.las"
    laspy.LasData(laspy.LasHeader(point_format=6, version="1.4")).write(str(path))
    thinning, to_local = (np.zeros(2), np.full(2, 10.0), 0.5, None), Shift(np.zeros(3))
    rule, kept = PointRule(use_class=True), []
    assert scan.native_scan(str(path), to_local, rule, None, thinning, []) is None
    got = scan.scan_unit((str(path), None, None), None, to_local, rule, None, thinning, False, None, kept)
    assert (got["points"], got["used"], got["cropped"], len(got["sums"][0]), kept) == (0, 0, 0, 0, [])


def test_a_thinner_is_fed_by_numpy_or_by_the_kernel_never_both(lib):
    """The kernel writes a column's first point over its sums (taken to be zero): a thinner numpy
    fed first, or numpy would feed after the kernel, is refused rather than summed wrong."""
    rec = _records(np.random.default_rng(9), 100, 1)
    origin = rec.offsets.copy()
    numpy_fed = ColumnThinner(np.full(2, -100.0), np.full(2, 100.0), 1.0)
    numpy_fed.add(np.zeros((3, 3)))
    with pytest.raises(RuntimeError, match="fed by numpy"):
        NativeChunks(lib, numpy_fed, None, None, origin, 100)
    kernel_fed = ColumnThinner(np.full(2, -100.0), np.full(2, 100.0), 1.0)
    NativeChunks(lib, kernel_fed, None, None, origin, 100).add(
        rec, None, Growing(100), Growing(0), Growing(0, None, np.uint8)
    )
    with pytest.raises(RuntimeError, match="fed by the native kernel"):
        kernel_fed.add(np.zeros((3, 3)))


def test_the_grid_index_finds_the_k_d_trees_neighbours(lib):
    """The ICP's searches on the kernel's bucket grid: for every point, the nearest target (none
    beyond the bound) and the distance to the second nearest that SciPy's k-d tree finds, on
    column surfaces (one point a cell), on random clouds (many a cell, or none), for points off
    the target's box and for a target of one point, within bounds up to none."""
    from scipy.spatial import cKDTree

    from soilvolume.registration.nearest import GridIndex

    rng = np.random.default_rng(7)
    gx, gy = np.meshgrid(np.arange(120) * 0.5, np.arange(80) * 0.5)
    surface = np.c_[gx.ravel(), gy.ravel(), 0.4 * np.sin(gx / 7).ravel()] + rng.normal(0, 0.02, (9600, 3))
    targets = (surface, rng.uniform(-30, 30, (5000, 3)), np.array([[1.0, 2.0, 3.0]]))
    for target in targets:
        tree, grid = cKDTree(target, balanced_tree=False), GridIndex(lib, target)
        near = target[rng.integers(0, len(target), 4000)] + rng.normal(0, 0.3, (4000, 3))
        far = rng.uniform(-200, 200, (500, 3))  # mostly off the target's box
        points = np.r_[near, far]
        for bound in (0.05, 0.6, 4.5, 40.0, np.inf):
            d, j = tree.query(points, k=2, distance_upper_bound=bound)
            idx, second = grid.nearest2(np.ascontiguousarray(points.T), bound)
            assert np.array_equal(idx, j[:, 0]), bound
            assert np.array_equal(second, np.minimum(d[:, 1], bound)), bound


def test_the_cut_kernel_gives_the_masks_points(lib, monkeypatch):
    """A registration target's cut to a box (``Cloud.within``) by the kernel: the points numpy's
    mask and compress keep, in order, from a cloud (N, 3) and from an earlier cut's (3, M) rows,
    edges included, none when the box misses the cloud."""
    from soilvolume.registration import columns

    rng = np.random.default_rng(4)
    xyz = np.round(rng.uniform(0, 50, (20_000, 3)), 1)  # points on the box's edges too
    for base in (xyz, np.ascontiguousarray(xyz.T).T):
        for lo, hi in (((10.0, 5.0), (30.0, 20.0)), ((0.0, 0.0), (50.0, 50.0)), ((60.0, 60.0), (70.0, 70.0))):
            lo, hi = np.array(lo), np.array(hi)
            fast = columns._cut(base, lo, hi)
            with monkeypatch.context() as m:
                m.setattr("soilvolume.native.kernels", lambda: None)  # the numpy path
                slow = columns._cut(base, lo, hi)
            assert fast.shape == slow.shape and fast.tobytes() == slow.tobytes()
    assert columns._cut(xyz, np.array([10.0, 5.0]), np.array([30.0, 20.0])).shape[1] > 0


def test_the_bounds_kernel_gives_numpys_min_and_max(lib, monkeypatch):
    """Bounds of float64 clouds by the kernel (one pass): numpy's per-axis min and max for rows,
    transposed rows, column slices and strided views, 1 to 3 axes, NaN where an axis has one."""
    from soilvolume.core import cells

    rng = np.random.default_rng(8)
    xyz = rng.normal(0, 100, (120_000, 3))
    nan = xyz.copy()
    nan[5_000, 1] = np.nan
    for a in (xyz, np.ascontiguousarray(xyz.T).T, xyz[:, :2], xyz[::3], xyz[:, 1:], nan):
        for dims in (None, 1, 2, 3):
            if dims is not None and dims > a.shape[1]:
                continue
            got = cells.bounds(a, dims)
            with monkeypatch.context() as m:
                m.setattr("soilvolume.native.kernels", lambda: None)  # the numpy path
                want = cells.bounds(a, dims)
            assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want, strict=True)), (a.strides, dims)
    lo, hi = cells.bounds(nan)
    assert np.isnan(lo[1]) and np.isnan(hi[1]) and np.isfinite(lo[[0, 2]]).all()


def test_the_window_cells_kernel_gives_the_numpy_bits(lib, monkeypatch):
    """A grid task's soil points on its window's cells (``gridtile._window_cells``) by the kernel:
    numpy's cell ids and heights, and the same offset sums bit for bit, chunk after chunk."""
    from soilvolume.dem import grid as gridmod
    from soilvolume.distributed import gridtile

    rng = np.random.default_rng(6)
    grid = gridmod.make_grid(np.array([0.0, 0.0]), np.array([60.0, 40.0]), 0.7, np.zeros(3), None)
    win = (10, 37, 21, 60)
    chunks = [
        np.c_[rng.uniform(-5, 65, n), rng.uniform(-5, 45, n), rng.normal(2, 0.3, n)].astype(np.float32)
        for n in (9_000, 4_000)
    ]
    chunks.append(np.ascontiguousarray(chunks[0].T).T)  # transposed rows, as a moved chunk may be

    def run():
        sums, out = gridmod.OffsetSums((win[1] - win[0]) * (win[3] - win[2])), []
        for c in chunks:
            ids, z = gridtile._window_cells(c, grid, win, sums)
            out += [ids.astype(np.int64).tobytes(), z.astype(np.float64).tobytes()]
        return out, sums.sx.tobytes(), sums.sy.tobytes()

    fast = run()
    with monkeypatch.context() as m:
        m.setattr("soilvolume.native.kernels", lambda: None)
        slow = run()
    assert fast == slow
    assert len(fast[0][0]) > 8 * 1_000  # a thousand points and more on the window


def test_the_first_chunk_is_read_mapped_as_it_is_read_into_buffers(tmp_path):
    """An epoch's rule is decided on its first chunk, read as views of the file mapped read-only:
    the same classes and signals as the buffered read, and a file shorter than its header says
    gives what it has (the run's own reading reports it)."""
    from soilvolume.inputs import records

    rng = np.random.default_rng(2)
    n = 5_000
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.x, las.y, las.z = rng.uniform(0, 60, n), rng.uniform(0, 40, n), rng.normal(0, 0.2, n)
    las.classification = rng.integers(1, 7, n).astype(np.uint8)
    las.red, las.green, las.blue = (rng.integers(0, 65_535, n).astype(np.uint16) for _ in range(3))
    path = tmp_path / "a.las"
    las.write(str(path))
    mapped = records.first_chunk_signals(path, n, 3_000, True)
    buffered = next(records.las_records(path, n, 3_000, True, piece=3_000, ring=1, stop=3_000))[1:]
    assert np.array_equal(mapped[0], las.classification[:3_000]) and np.array_equal(mapped[0], buffered[0])
    assert np.array_equal(mapped[1].rgb, buffered[1].rgb) and np.array_equal(mapped[1].returns, buffered[1].returns)
    short = tmp_path / "short.las"
    short.write_bytes(path.read_bytes()[: -(n - 1_000) * las.header.point_format.size])
    cls, _ = records.first_chunk_signals(short, n, 3_000, True)
    assert np.array_equal(cls, las.classification[:1_000])
