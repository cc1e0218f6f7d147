"""Start-up and streaming costs (issue 22): what a run imports and when, and the in-place shift of
the chunks the reader allocated (never of a cloud already in memory)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import run_python, write_scene

from soilvolume.inputs.crs import Shift
from soilvolume.inputs.io import RawPoints
from soilvolume.inputs.stream import ColumnThinner, from_raw, load, open_source


def test_engine_modules_leave_the_heavy_libraries_to_the_run(tmp_path):
    """Importing the CLI and the engine's products (the project's own modules at the top of their
    files) imports none of Open3D, rasterio, SciPy's submodules, shapely or Jinja2 (heavy libraries,
    imported by the steps that use them: ``soilvolume estimate --help`` stays quick)."""
    b, _, _ = write_scene(tmp_path)
    code = (
        "import sys, json\n"
        "import soilvolume.cli, soilvolume.workflow.estimate\n"
        "from soilvolume.inputs.stream import open_source\n"
        f"n = open_source({str(b)!r}).count\n"
        f"mods = ('laspy', *{HEAVY!r})\n"
        "print(json.dumps([n] + [m in sys.modules for m in mods]))\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    count, laspy, *heavy = json.loads(r.stdout)
    assert count > 1000 and laspy
    assert dict(zip(HEAVY, heavy, strict=True)) == dict.fromkeys(HEAVY, False)


def test_a_command_loads_its_own_workflow_not_the_others():
    """The estimate's command module imports the estimate's workflow, not the series', the DEM's or the
    rasters' (the public ``soilvolume.api`` imports them all: the command line goes round it)."""
    code = (
        "import sys, json\n"
        "import soilvolume.cli.estimate\n"
        "mods = ('soilvolume.workflow.estimate', 'soilvolume.api', 'soilvolume.workflow.series', "
        "'soilvolume.workflow.commands', 'soilvolume.workflow.rasters')\n"
        "print(json.dumps([m in sys.modules for m in mods]))\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == [True, False, False, False, False]


HEAVY = ("open3d", "rasterio", "scipy.optimize", "scipy.ndimage", "scipy.sparse", "scipy.spatial", "shapely", "jinja2")


def ahead_probe(argv: list[str]) -> str:
    """The command's entry run with ``argv``: which of :data:`soilvolume.process.AHEAD` are loaded
    before the native reading says it runs without the GIL, and once it has."""
    body = [
        "import threading, time",
        "from soilvolume.native import OFF_THE_GIL",
        "from soilvolume.process import AHEAD",
        "ahead = [t for t in threading.enumerate() if t.name == 'soilvolume-import-ahead']",
        "time.sleep(0.3)",
        "held = [m in sys.modules for m in AHEAD]",
        "OFF_THE_GIL.set()",
        "[t.join(60) for t in ahead]",
        "print(json.dumps([len(ahead), held, [m in sys.modules for m in AHEAD]]))",
        "return 0",
    ]
    return f"import sys; sys.argv = {['soilvolume', *argv]!r}\n" + entry_probe("json", body)


def test_a_run_imports_its_heavy_libraries_while_the_kernel_reads():
    """``soilvolume estimate ...`` imports what its later steps use (:data:`soilvolume.process.AHEAD`)
    in one background thread, and only while the native kernel reads without the GIL
    (``native.OFF_THE_GIL``); ``--help`` and ``pipeline`` start no thread."""
    r = run_python(ahead_probe(["estimate", "a.las", "b.las", "--out", "o"]))
    assert r.returncode == 0, r.stderr
    threads, held, loaded = json.loads(r.stdout.splitlines()[-1])
    assert threads == 1 and not any(held) and all(loaded), (held, loaded)
    for argv in (["estimate", "--help"], ["pipeline", "x.json"]):
        r = run_python(ahead_probe(argv))
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout.splitlines()[-1])[0] == 0, argv


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver workers on Linux only")
def test_local_workers_are_forked_from_a_server_that_imported_their_modules():
    """A local cluster's workers come from one forkserver that imported Dask and the tasks'
    modules once (a spawned worker imports them itself, ~0.6 s of CPU each, while the driver
    reads), frozen out of the collector's reach (:mod:`soilvolume.distributed.forkfreeze`); Dask's pre-spawn
    environment (one BLAS/OpenMP thread per worker) still reaches them and their server, which starts before Dask
    is imported."""
    code = (
        "import json, os, pathlib, sys, tempfile\n"
        "os.environ.pop('MALLOC_TRIM_THRESHOLD_', None)\n"
        "from soilvolume.distributed import cluster\n"
        "scratch = tempfile.TemporaryDirectory()  # the workers' scratch space, removed at exit\n"
        "c, client = cluster.local(2, True, 1.0, pathlib.Path(scratch.name))\n"
        "try:\n"
        "    info = client.run(lambda: (os.getppid(), os.environ.get('OMP_NUM_THREADS'),\n"
        "                               'soilvolume.distributed.tiletask' in sys.modules,\n"
        "                               open(f'/proc/{os.getppid()}/environ').read().split(chr(0)),\n"
        "                               [sys.modules.get(m, 0) for m in ('requests', 'jinja2')],\n"
        "                               __import__('gc').get_freeze_count()))\n"
        "finally:\n"
        "    cluster.shut(c, client)\n"
        "print(json.dumps([os.getpid(), sorted(info.values())]))\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    driver, workers = json.loads(r.stdout.splitlines()[-1])
    assert len(workers) == 2
    parents = {w[0] for w in workers}
    assert len(parents) == 1 and driver not in parents  # one server forked both (spawned: the driver)
    assert all(w[1] == "1" and w[2] for w in workers)
    assert all(w[4] == [None, None] for w in workers)  # the extras hidden (process.hide_extras) before Dask and laspy
    assert all(w[5] > 10_000 for w in workers), [w[5] for w in workers]  # the server's imports frozen (~64,000)
    # the server started before any nanny set Dask's pre-spawn environment: it had it from its start
    # (OpenBLAS reads its threads as the server imports numpy), but for Dask's malloc trim threshold
    # (cluster.LOCAL_WORKER_ENV: glibc's own, as in-process)
    assert all("OMP_NUM_THREADS=1" in w[3] for w in workers)
    assert not any(e.startswith("MALLOC_TRIM_THRESHOLD_=") for w in workers for e in w[3])


def test_fresh_chunks_are_shifted_in_place_a_cloud_in_memory_never(tmp_path):
    origin = np.array([100.0, 200.0, 10.0])
    shift = Shift(origin)
    xyz = np.random.default_rng(0).uniform(0, 50, (1000, 3)) + origin
    expected = xyz - origin
    assert np.array_equal(shift(xyz), expected)
    moved = xyz.copy()
    assert np.array_equal(shift.inplace(moved), expected) and np.array_equal(moved, expected)
    # a cloud already in memory (non-LAS input, pipeline output) is one chunk: it stays as it was
    raw = RawPoints(xyz.copy(), None, None, "mem.ply", None)
    src = from_raw(raw)
    thinner = ColumnThinner(np.zeros(2), np.full(2, 60.0), 1.0)
    got = load(src, shift, "none", None, thinner)
    assert np.array_equal(raw.xyz, xyz)
    assert np.allclose(got.xyz, expected.astype(np.float32))
    # a LAS file read chunk by chunk: the same local points as the copying shift
    b, _, _ = write_scene(tmp_path)
    las = open_source(b)
    o = np.floor(las.lo)
    a1 = load(las, Shift(o), "none", None, ColumnThinner(las.lo[:2] - o[:2] - 1, las.hi[:2] - o[:2] + 1, 1.0))
    a2 = load(las, lambda p: p - o, "none", None, ColumnThinner(las.lo[:2] - o[:2] - 1, las.hi[:2] - o[:2] + 1, 1.0))
    assert np.array_equal(a1.xyz, a2.xyz) and np.array_equal(a1.thin, a2.thin)


def test_fast_kernels_match_the_plain_numpy_ones():
    """The per-column bounds and row compress equal numpy's axis-0 reductions and boolean
    indexing; the thinning sums over a chunk's span of columns equal the sums over the whole grid
    (chunks inside, partly outside and wholly outside the box)."""
    from soilvolume.core.cells import bounds, rows

    rng = np.random.default_rng(3)
    for dtype in (np.float64, np.float32):
        xyz = rng.uniform(-5, 65, (20_000, 3)).astype(dtype)
        mask = rng.random(len(xyz)) < 0.7
        lo, hi = bounds(xyz)
        assert np.array_equal(lo, xyz.min(axis=0)) and np.array_equal(hi, xyz.max(axis=0))
        assert np.array_equal(bounds(xyz, 2)[1], xyz[:, :2].max(axis=0)) and np.array_equal(rows(xyz, mask), xyz[mask])
    xyz = rng.uniform(-5, 65, (20_000, 3))
    new, whole = ColumnThinner(np.zeros(2), np.full(2, 60.0), 1.0), np.zeros((4, 61 * 61))
    for part in (xyz[:5000], xyz[5000:], xyz[:0], xyz[xyz[:, 0] > 61]):
        new.add(part)
        ix, iy = part[:, 0].astype(np.int64), part[:, 1].astype(np.int64)  # as before: truncation
        ok = (ix >= 0) & (iy >= 0) & (ix < 61) & (iy < 61)
        ids = iy[ok] * 61 + ix[ok]
        whole[3] += np.bincount(ids, minlength=whole.shape[1])
        for k in range(3):
            whole[k] += np.bincount(ids, weights=part[ok, k], minlength=whole.shape[1])
    assert np.array_equal(new.sums, whole)


def test_a_stage_timed_within_another_is_left_out_of_it(monkeypatch):
    """``cluster_wait`` timed inside ``crop`` (the cluster waited for at its first use): each
    counts its own time and the stages still add up to the wall time."""
    import time as clock

    from soilvolume.workflow.context import Timer

    now = [100.0]
    monkeypatch.setattr(clock, "perf_counter", lambda: now[0])
    t = Timer()
    with t("crop"):
        now[0] += 1.0
        with t("cluster_wait"):
            now[0] += 2.0
        now[0] += 0.5
    with t("grids"):
        now[0] += 0.25
        assert t.totals()["grids"] == 0.25  # a stage still open counts what ran so far
    s = t.totals()
    assert (s["crop"], s["cluster_wait"], s["grids"]) == (1.5, 2.0, 0.25)
    assert sum(v for k, v in s.items() if k != "startup") == 3.75


def entry_probe(imports: str, body: list[str]) -> str:
    """A program running ``python -m soilvolume``'s entry (``soilvolume.__main__.run``) with the
    command line replaced by a ``main`` of the lines ``body``, after ``import <imports>``."""
    return (
        f"import {imports}, sys, types\n"
        "cli = types.ModuleType('soilvolume.cli')\n"  # stands in for the command line
        "def main():\n" + "".join(f"    {line}\n" for line in body) + "cli.main = main\n"
        "sys.modules['soilvolume.cli'] = cli\n"
        "import soilvolume.__main__\n"
        "soilvolume.__main__.run()\n"
    )


BLAS_PROBE = entry_probe(  # what does numpy see?
    "os",
    [
        "import numpy as np",
        "np.ones((300_000, 3)) @ np.eye(3)  # a product OpenBLAS threads",
        "print(len(os.listdir('/proc/self/task')), os.environ.get('OPENBLAS_NUM_THREADS'))",
        "return 0",
    ],
)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_the_command_runs_numpy_blas_on_one_thread_unless_the_user_says_otherwise(monkeypatch):
    """The command's process loads numpy with OpenBLAS on one thread (idle BLAS threads spin after
    every product, ~1.3 s of system time in a paper-sized run); a user's OPENBLAS_NUM_THREADS wins."""
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    r = run_python(BLAS_PROBE)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["1", "1"]  # the main thread alone
    if (os.cpu_count() or 1) > 1:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
        r = run_python(BLAS_PROBE)
        assert r.returncode == 0, r.stderr
        threads, setting = r.stdout.split()
        assert int(threads) >= 2 and setting == "2"  # OpenBLAS's own thread beside the main one


def test_the_command_leaves_without_the_interpreters_teardown_its_output_flushed():
    """Once the command returned, the process ends with its exit status (``process.leave``):
    what it printed is out, and nothing of the interpreter's teardown (here an ``atexit``
    handler) runs."""
    probe = entry_probe("atexit", ["atexit.register(lambda: print('teardown'))", "print('done', end='')", "return 3"])
    r = run_python(probe)
    assert r.returncode == 3 and r.stdout == "done", (r.stdout, r.stderr)


def test_the_command_hides_the_optional_extras_from_laspy_and_dask():
    """The command's process sees requests as not installed (``process.hide_extras``): laspy and
    Dask import without it and work; jinja2 (report.html) stays importable."""
    probe = entry_probe(
        "json",
        [
            "import laspy, dask.distributed",
            "import jinja2",
            "print(json.dumps([sys.modules.get('requests', 0), jinja2.__name__, laspy.__name__]))",
            "return 0",
        ],
    )
    r = run_python(probe)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.splitlines()[-1]) == [None, "jinja2", "laspy"]
