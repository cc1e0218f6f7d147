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

from soilvolume.inputs.io import RawPoints
from soilvolume.inputs.prepare import Shift
from soilvolume.inputs.stream import ColumnThinner, from_raw, load, open_source


def test_engine_modules_leave_open3d_rasterio_and_requests_to_the_run(tmp_path):
    """Importing the CLI and the engine's products (the project's own modules at the top of their
    files) imports neither Open3D nor rasterio (the preload thread does, while the clouds are
    read), and reading a LAS header does not import requests."""
    b, _, _ = write_scene(tmp_path)
    code = (
        "import sys, json\n"
        "import soilvolume.cli, soilvolume.workflow.estimate\n"
        "from soilvolume.inputs.stream import open_source\n"
        f"n = open_source({str(b)!r}).count\n"
        "mods = ('open3d', 'rasterio', 'requests', 'laspy', 'scipy.optimize')\n"
        "print(json.dumps([n] + [m in sys.modules for m in mods]))\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    count, open3d, rasterio, requests, laspy, optimize = json.loads(r.stdout)
    assert count > 1000 and laspy
    assert not open3d and not rasterio and not requests and not optimize


def test_a_dask_worker_starts_without_scipy_spatial():
    """What a worker imports as it starts (workerinit.warm: the scan and grid tasks' modules) leaves
    out SciPy's spatial module (~0.2 s per worker): only the driver makes footprints (hulls)."""
    code = (
        "import sys\n"
        "from soilvolume.distributed.workerinit import warm\n"
        "warm()\n"
        "print('scipy.spatial' in sys.modules, 'soilvolume.distributed.tiletask' in sys.modules)\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver workers on Linux only")
def test_local_workers_are_forked_from_a_server_that_imported_their_modules():
    """A local cluster's workers come from one forkserver that imported Dask and the tasks'
    modules once (a spawned worker imports them itself, ~0.6 s of CPU each, while the driver
    reads); Dask's pre-spawn environment (one BLAS/OpenMP thread per worker) still reaches them and
    their server, which starts before Dask is imported. The server imports with the garbage
    collector paused; the workers have it on, the server's imports frozen out of it."""
    code = (
        "import gc, json, os, sys\n"
        "os.environ.pop('MALLOC_TRIM_THRESHOLD_', None)\n"
        "from soilvolume.distributed import cluster\n"
        "c, client = cluster.local(2, True, 1.0, None)\n"
        "try:\n"
        "    info = client.run(lambda: (os.getppid(), os.environ.get('OMP_NUM_THREADS'),\n"
        "                               'soilvolume.distributed.tiletask' in sys.modules,\n"
        "                               open(f'/proc/{os.getppid()}/environ').read().split(chr(0)),\n"
        "                               gc.isenabled(), gc.get_freeze_count(),\n"
        "                               [m in sys.modules for m in ('laspy', 'requests', 'jinja2')],\n"
        "                               [sys.modules.get(m, 0) is None for m in ('requests', 'jinja2')],\n"
        "                               __import__('yaml').safe_load.__name__))\n"
        "finally:\n"
        "    cluster.shut(c, client)\n"
        "print(json.dumps([os.getpid(), sorted(info.values()), 'jinja2' in sys.modules]))\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    driver, workers, jinja2 = json.loads(r.stdout.splitlines()[-1])
    assert len(workers) == 2
    parents = {w[0] for w in workers}
    assert len(parents) == 1 and driver not in parents  # one server forked both (spawned: the driver)
    assert all(w[1] == "1" and w[2] for w in workers)
    assert all(w[4] and w[5] > 10_000 for w in workers)  # collector on, the server's imports frozen
    # laspy without requests, Dask without jinja2 (core.leanimport.EXTRAS), importable again after
    assert all(w[6] == [True, False, False] and w[7] == [False, False] for w in workers) and not jinja2
    assert all(w[8] == "safe_load" for w in workers)  # PyYAML's own again (LibYAML's while the server imported)
    # the server started before any nanny set Dask's pre-spawn environment: it had it from its start
    # (OpenBLAS reads its threads as the server imports numpy), but for Dask's malloc trim threshold
    # (cluster.LOCAL_WORKER_ENV: glibc's own, as in-process)
    assert all("OMP_NUM_THREADS=1" in w[3] for w in workers)
    assert not any(e.startswith("MALLOC_TRIM_THRESHOLD_=") for w in workers for e in w[3])


def test_imports_inside_without_see_the_extras_as_not_installed_and_after_it_as_installed():
    """:func:`leanimport.without`: a module not imported yet cannot be imported inside (as if not
    installed: a library's optional extra is then left out), and can be after it; one imported
    already stays as it is."""
    code = (
        "import importlib, json, sys\n"
        "from soilvolume.core.leanimport import without\n"
        "import tabnanny\n"
        "with without(('colorsys', 'tabnanny')):\n"
        "    try:\n"
        "        import colorsys\n"
        "        inside = 'imported'\n"
        "    except ModuleNotFoundError:\n"
        "        inside = 'not installed'\n"
        "    again = importlib.import_module('tabnanny') is sys.modules['tabnanny']\n"
        "import colorsys\n"
        "print(json.dumps([inside, again, colorsys.__name__]))\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.splitlines()[-1]) == ["not installed", True, "colorsys"]


def test_yaml_inside_fast_yaml_is_libyamls_with_the_same_documents_and_pyyamls_after_it():
    """:func:`leanimport.fast_yaml` (around Dask's and Distributed's imports, which parse their
    defaults): ``yaml.safe_load`` gives what PyYAML's own loader gives, and is PyYAML's after."""
    from pathlib import Path

    import distributed
    import yaml

    from soilvolume.core.leanimport import fast_yaml

    text = (Path(distributed.__file__).parent / "distributed.yaml").read_text(encoding="utf-8")
    plain = yaml.safe_load
    with fast_yaml():
        inside, fast = yaml.safe_load(text), yaml.safe_load
    assert inside == plain(text) and inside["distributed"]["nanny"]["pre-spawn-environ"]
    assert yaml.safe_load is plain and (fast is not plain) == hasattr(yaml, "CSafeLoader")


def test_preload_imports_open3d_during_the_reading_and_the_later_steps_after_it():
    """Open3D while the clouds are read; the registration's and volume step's modules (ndimage)
    and rasterio only once the reading is done (an import beside the reading slows it; the
    memory peak is behind)."""
    code = (
        "import sys, time\n"
        "from soilvolume.core.preload import AFTER_READING, preload, reading_done\n"
        "t = preload(True, threads=1)\n"
        "t0 = time.time()\n"
        "while 'open3d' not in sys.modules and time.time() < t0 + 60:\n"
        "    time.sleep(0.05)  # not imported here: the preload thread imports it\n"
        "time.sleep(0.3)\n"
        "early = [m in sys.modules for m in ('scipy.ndimage', *AFTER_READING)]\n"
        "reading_done(); t.join(60)\n"
        "import os\n"
        "late = all(m in sys.modules for m in ('scipy.ndimage', *AFTER_READING))\n"
        "print(time.time() < t0 + 60, any(early), late, os.environ['OMP_NUM_THREADS'], not t.is_alive())\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "False", "True", "1", "True"]


def test_preload_goes_ahead_while_a_tiled_driver_waits_for_its_first_pass():
    """A tiled run's driver, waiting on its workers' tasks (``idle``), lets the held-back imports
    go ahead before its reading is done."""
    code = (
        "import sys\n"
        "from soilvolume.core.preload import AFTER_READING, idle, preload\n"
        "t = preload(False)\n"
        "t.join(0.3)\n"
        "early = any(m in sys.modules for m in AFTER_READING)\n"
        "idle(); t.join(60)\n"
        "print(early, all(m in sys.modules for m in AFTER_READING), t.is_alive())\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True", "False"]


def test_preload_imports_each_epochs_stage_beside_its_native_reading():
    """The kernel reading an epoch's files without the GIL lets that epoch's stage of the held-back
    imports go ahead, however many files (tiles) it has: SciPy's spatial beside the after cloud
    (the footprint needs it next), the later steps' modules beside the before cloud, none of them
    beside the Python between the two (the footprint, the crop's mask: an import there holds the
    GIL they wait for)."""
    code = (
        "import sys, time\n"
        "from soilvolume.core.preload import STAGES, off_the_gil, preload, reading_epoch\n"
        "t = preload(False)\n"
        "def now(stage):\n"
        "    t.join(0.3)\n"
        "    return ''.join('1' if m in sys.modules else '0' for m in stage)\n"
        "seen = [now(STAGES[0])]\n"
        "reading_epoch(0)\n"
        "for tile in range(3):\n"
        "    off_the_gil()  # the after cloud's tiles, one window each\n"
        "t0 = time.time()\n"
        "while STAGES[0][-1] not in sys.modules and time.time() < t0 + 60:\n"
        "    time.sleep(0.02)\n"
        "seen += [now(STAGES[0]), now(STAGES[1])]\n"
        "reading_epoch(1)\n"
        "seen.append(now(STAGES[1]))  # between the epochs: not yet\n"
        "off_the_gil(); t.join(60)\n"
        "seen += [now(STAGES[1]), str(t.is_alive())]\n"
        "print(*seen)\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["0", "1", "000", "000", "111", "False"]


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


def test_large_runs_keep_freed_memory(monkeypatch):
    """Only a run over the large-run size changes the allocator's thresholds, once."""
    import sys

    from soilvolume.core import heap

    monkeypatch.setattr(heap, "_done", False)
    assert not heap.keep_freed_memory(1_000_000)
    if sys.platform.startswith("linux"):
        assert heap.keep_freed_memory(heap.LARGE_RUN_POINTS + 1)
        assert not heap.keep_freed_memory(heap.LARGE_RUN_POINTS + 1)  # once per process


def test_a_stage_timed_within_another_is_left_out_of_it(monkeypatch):
    """``cluster_wait`` timed inside ``crop`` (the cluster waited for at its first use): each
    counts its own time and the stages still add up to the wall time."""
    import time as clock

    from soilvolume.workflow.timing import Timer

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


PAGES_PROBE = entry_probe(  # does numpy ask for huge pages?
    "os",
    [
        "import numpy as np",
        "print(np.core.multiarray._set_madvise_hugepage(True), os.environ.get('NUMPY_MADVISE_HUGEPAGE'))",
        "return 0",
    ],
)


def test_the_command_keeps_numpy_off_huge_pages_unless_the_user_says_otherwise(monkeypatch):
    """The command's process loads numpy without its transparent-huge-page advice (on a VM that
    reports free memory to its host, each huge page faulted in is zeroed again there: the reading
    took 0.2 s more in 2 of 3 runs); a user's NUMPY_MADVISE_HUGEPAGE wins."""
    monkeypatch.delenv("NUMPY_MADVISE_HUGEPAGE", raising=False)
    r = run_python(PAGES_PROBE)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "0"]  # numpy loaded with the advice off
    monkeypatch.setenv("NUMPY_MADVISE_HUGEPAGE", "1")
    r = run_python(PAGES_PROBE)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "1"]


def _collector_probe(args: list[str]) -> list:
    """[collector paused while the command line loaded, on after the command, objects frozen, exit
    code] of the command ``args`` run through ``python -m soilvolume``'s entry."""
    probe = entry_probe(
        "gc, json",
        [
            "paused = not gc.isenabled()",
            "del sys.modules['soilvolume.cli']  # the real command line from here",
            "import soilvolume.cli as real",
            f"code = real.main({args!r})",
            "print(json.dumps([paused, gc.isenabled(), gc.get_freeze_count() > 1000, code]))",
            "return code",
        ],
    )
    r = run_python(probe, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.splitlines()[-1])


def test_the_command_loads_its_modules_without_the_garbage_collector_and_the_run_restarts_it(tmp_path):
    """The command line pauses Python's cyclic collector while its modules load; a run restarts it
    once its inputs are read (a command without a pair, after its first step), what was loaded
    frozen out of later passes; the result is the one a run with the collector on all along gives.
    A program importing the engine keeps its collector."""
    b, a, _ = write_scene(tmp_path)
    assert _collector_probe(["estimate", str(b), str(a), "--out", str(tmp_path / "cli"), "--quiet"]) == [True] * 3 + [0]
    assert _collector_probe(["dem", str(a), "--out", str(tmp_path / "dem.tif")]) == [True] * 3 + [0]
    import gc

    from soilvolume.api import estimate

    enabled = gc.isenabled()
    result = estimate(b, a, tmp_path / "api")
    assert gc.isenabled() == enabled  # not paused by the engine: nothing to resume
    ours = json.loads((tmp_path / "cli" / "report.json").read_text())["volume_m3"]
    assert ours == result.report["volume_m3"]


def test_the_command_imports_pyproj_without_its_network_modules_and_pyproj_still_works(tmp_path):
    """A run through ``python -m soilvolume``'s entry never imports pyproj's grid downloads
    (urllib.request, http.client, ssl) or importlib.metadata, ~25 ms of start-up; the functions
    that need them still work, and a later ``import pyproj.sync`` is the real module."""
    b, a, _ = write_scene(tmp_path)
    args = ["estimate", str(b), str(a), "--out", str(tmp_path / "out")]
    probe = entry_probe(
        "json",
        [
            "del sys.modules['soilvolume.cli']",
            "import soilvolume.cli as real",
            f"code = real.main({args!r})",
            "mods = ('urllib.request', 'http.client', 'ssl', 'importlib.metadata')",
            "out = [code] + [m in sys.modules for m in mods]",
            "import pyproj, pyproj.sync, pyproj.transformer",
            "deferred = pyproj.transformer._download_resource_file",
            "out += [callable(pyproj.sync.get_user_data_dir), type(deferred).__name__]",
            "pyproj.show_versions()",
            "print(json.dumps(out))",
            "return 0",
        ],
    )
    r = run_python(probe, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "pyproj:" in r.stdout  # show_versions printed the real report
    assert json.loads(r.stdout.splitlines()[-1]) == [0, False, False, False, False, True, "function"]


def test_the_command_line_alone_imports_no_pyproj_and_the_first_import_is_the_lean_one():
    """``python -m soilvolume``'s entry loads pyproj only when a command imports it (``--help``
    never does), and that first import is the lean one, after which the hook is gone."""
    probe = entry_probe(
        "json",
        [
            "del sys.modules['soilvolume.cli']",
            "import soilvolume.cli",
            "hooked = lambda: any(type(f).__name__ == '_Finder' for f in sys.meta_path)",
            "out = ['pyproj' in sys.modules, hooked()]",
            "import pyproj",
            "out += [hooked(), 'urllib.request' in sys.modules, type(pyproj.__spec__.loader).__name__]",
            "print(json.dumps(out))",
            "return 0",
        ],
    )
    r = run_python(probe)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.splitlines()[-1]) == [False, True, False, False, "_Loader"]


def test_a_pyproj_that_uses_a_stand_in_while_it_loads_is_imported_the_ordinary_way(tmp_path):
    """Should a pyproj release use ``pyproj.sync`` at import time, it is loaded again without the
    stand-ins (a fake pyproj here: its ``__init__`` adds to a constant of its sync module)."""
    pkg = tmp_path / "pyproj"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from pyproj.sync import LEVEL\nVALUE = LEVEL + 1\n")
    (pkg / "sync.py").write_text("LEVEL = 41\n")
    code = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r})\n"
        "from soilvolume.core import leanimport\n"
        "leanimport.install()\n"
        "import pyproj, pyproj.sync\n"
        "print(pyproj.VALUE, type(pyproj.sync).__name__)\n"
    )
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["42", "module"]
