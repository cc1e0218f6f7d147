"""The hostile-input corpus: every way a hostile user broke the tiled engine, its VPC/COPC inputs,
its schedulers, zones and stable masks, run as that user runs it (``python -m soilvolume``, its
own process). Each case: the command, the exit code, a pattern of the one line (stderr for a
failure, stdout for a result), the inputs byte-identical afterwards, nothing written outside
``--out`` (nor in the temporary folder), and done within 60 s.

The cases run concurrently (they wait on sockets and clusters as often as they compute), each in
a folder of its own; the inputs are one read-only folder (:mod:`hostile_inputs`). Below the
table: the cases that take more than one command (an interrupted run resumed after an input
changed, Ctrl-C and SIGTERM of a LocalCluster run, two runs into one ``--out``).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from hostile_inputs import Server, free_port, write_inputs

LIMIT_S = 60.0
PARALLEL = 3


@dataclass(frozen=True)
class Case:
    """``args`` may name ``{in}`` (the inputs folder), ``{out}`` (this case's output folder) and
    the servers ``{silent}``, ``{garbage}``, ``{closed}``, ``{idle}`` (a Dask scheduler without
    workers). ``line``: a regex of the one stderr line (exit != 0) or of stdout (exit 0);
    ``report``: a check of report.json."""

    id: str
    args: tuple[str, ...]
    code: int
    line: str
    report: Callable[[dict], None] | None = None

    @property
    def waits(self) -> bool:
        """Whether the case mostly waits on a server (it runs beside the others, not in turn)."""
        return any(s in a for a in self.args for s in ("{silent}", "{garbage}", "{closed}", "{idle}"))


def est(*args: str) -> tuple[str, ...]:
    """An ``estimate`` of the corpus pair (or of other inputs given first) into ``{out}``."""
    inputs = args[:2] if args and not args[0].startswith("-") else ("{in}/before.las", "{in}/after.las")
    rest = args[2:] if inputs == args[:2] else args
    return ("estimate", *inputs, "--out", "{out}", "--quiet", *rest)


def vpc(name: str, *args: str) -> tuple[str, ...]:
    return est(f"{{in}}/{name}.vpc", "{in}/after.vpc", *args)


def verdict(want: str, *words: str) -> Callable[[dict], None]:
    def check(report: dict) -> None:
        q = report["quality"]
        assert q["verdict"] == want, q
        for w in words:
            assert any(w in m for m in q["messages"]), (w, q["messages"])

    return check


def never_not_significant(report: dict) -> None:
    """Unseen change is not "no change"."""
    assert not any("not significant" in m for m in report["quality"]["messages"]), report["quality"]


def zones_flag(key: str, value) -> Callable[[dict], None]:
    def check(report: dict) -> None:
        assert any(z.get(key) == value for z in report["zones"]), report["zones"]

    return check


TILED = ("--scheduler", "threads:2", "--volume-step", "tiles", "--tile-cells", "16")
ERR = 1
CASES = [
    # waits on other processes and clusters: each ends within its timeout
    Case("tcp-silent-server", est("--scheduler", "tcp://127.0.0.1:{silent}"), ERR, r"no answer within \d+ s"),
    Case("tcp-no-workers", est("--scheduler", "{idle}"), ERR, r"the Dask cluster has no workers"),
    Case("tcp-nothing-listening", est("--scheduler", "tcp://127.0.0.1:{closed}"), ERR, r"cannot reach the Dask"),
    Case("tcp-garbage-server", est("--scheduler", "tcp://127.0.0.1:{garbage}"), ERR, r"does not speak Dask's protocol"),
    Case("memory-below-a-worker", est("--memory-limit", "0.001", "--scheduler", "local:2"), ERR, r"below the 0.25 GB"),
    Case("memory-1e-9-auto", est("--memory-limit", "1e-9"), ERR, r"--memory-limit 1e-09: .* below"),
    Case("memory-1e-9-threads", est("--memory-limit", "1e-9", "--scheduler", "threads:1"), ERR, r"cannot hold a tile"),
    Case("workers-1000", est("--scheduler", "local:1000"), ERR, r"below the 0.25 GB a worker needs; use fewer"),
    Case("tile-too-large", est(*TILED[:2], "--tile-cells", "5000", "--memory-limit", "0.001"), ERR, r"smaller --tile"),
    # scheduler addresses
    Case("tcp-no-host", est("--scheduler", "tcp://"), ERR, r"--scheduler: no host"),
    Case("tls", est("--scheduler", "tls://10.0.0.1:8786"), ERR, r"TLS clusters need certificates"),
    Case("port-out-of-range", est("--scheduler", "tcp://localhost:99999"), ERR, r"port must be a number from 1"),
    Case("port-zero", est("--scheduler", "tcp://localhost:0"), ERR, r"port must be a number from 1"),
    Case("port-not-a-number", est("--scheduler", "tcp://localhost:http"), ERR, r"port must be a number"),
    Case("address-with-path", est("--scheduler", "tcp://h:1/x?y"), ERR, r"tcp://HOST:PORT, nothing more"),
    Case("other-protocol", est("--scheduler", "ucx://h:1"), ERR, r"unsupported protocol 'ucx://'"),
    Case("zero-workers", est("--scheduler", "local:0"), ERR, r"N from 1 to 1024"),
    Case("filter-on-tiles", est("--scheduler", "threads:2", "--ground", "filter"), ERR, r"--ground filter needs"),
    Case(
        "pipeline-on-a-cluster",
        est("--scheduler", "threads:2", "--before-pipeline", "{in}/pipeline.json"),
        ERR,
        r"pipelines run in-process only",
    ),
    # the command line: one line, exit 2 (argparse) or 1 (ranges)
    Case("cell-not-a-number", est("--cell", "abc"), 2, r"^soilvolume: error: --cell: invalid float value: 'abc'$"),
    Case("choice-unknown", est("--fine", "best"), 2, r"^soilvolume: error: --fine: invalid choice: 'best'"),
    Case("flag-unknown", est("--frobnicate"), 2, r"unrecognized arguments: --frobnicate"),
    Case("tile-cells-float", est("--tile-cells", "1.5"), 2, r"--tile-cells: invalid int value"),
    Case("no-out", ("estimate", "{in}/before.las", "{in}/after.las"), 2, r"required: --out"),
    Case("no-command", (), 2, r"required: command"),
    Case("cell-nan", est("--cell", "nan"), ERR, r"--cell: must be a finite number"),
    Case("memory-negative", est("--memory-limit", "-1"), ERR, r"--memory-limit: must be"),
    Case("tile-cells-negative", est("--tile-cells", "-5"), ERR, r"--tile-cells: must be"),
    # VPC structure: validated against the STAC fields read, the field named
    Case("vpc-top-level-list", vpc("list"), ERR, r"list\.vpc: the document must be a STAC FeatureCollection object"),
    Case("vpc-feature-not-object", vpc("feature_string"), ERR, r"features\[1\] must be an object \(got a string\)"),
    Case("vpc-assets-not-object", vpc("assets_list"), ERR, r"\.assets must be an object of assets"),
    Case("vpc-asset-not-object", vpc("asset_string"), ERR, r"\.assets\.data must be an object"),
    Case("vpc-count-many", vpc("count_many"), ERR, r"pc:count must be a non-negative integer \(got a string\)"),
    Case("vpc-count-wrong", vpc("count_wrong"), ERR, r"pc:count 12 but the header of before_1\.laz says"),
    Case("vpc-bbox-string", vpc("bbox_string"), ERR, r"proj:bbox must be a list of 4 or 6 finite numbers"),
    Case("vpc-bbox-three", vpc("bbox_three"), ERR, r"proj:bbox must be a list of 4 or 6 .*got 3 values"),
    Case("vpc-wkt-garbage", vpc("wkt_garbage"), ERR, r"proj:wkt2 is not a CRS pyproj can read"),
    Case("vpc-epsg-string", vpc("epsg_string"), ERR, r"proj:epsg must be a positive integer"),
    Case("vpc-box-wrong", vpc("box_shifted"), ERR, r"its proj:bbox does not match the header of before_3\.laz"),
    Case("vpc-wgs84-box-wrong", vpc("wgs84_shifted"), ERR, r"bbox \(WGS 84\) does not match the header of before_2"),
    Case("vpc-latitude", vpc("lat_out_of_range"), ERR, r"bbox must be WGS 84 longitudes and latitudes"),
    Case("vpc-no-tiles", vpc("empty"), ERR, r"'features' is empty"),
    Case("vpc-tile-twice", vpc("duplicate"), ERR, r"lists the tile .*before_0\.laz that features\[0\]"),
    Case("vpc-href-system-file", vpc("href_passwd"), ERR, r"tile /etc/passwd is not a LAS/LAZ file \(its name"),
    Case("vpc-href-content-not-echoed", vpc("href_passwd_laz"), ERR, r"secrets\.laz: not a readable LAS/LAZ file"),
    Case("vpc-tile-is-a-folder", vpc("href_folder"), ERR, r"tile folder\.laz is a folder, not a LAS/LAZ file"),
    Case("vpc-tile-missing", vpc("href_missing"), ERR, r"tile gone\.laz not found"),
    Case("vpc-tile-remote", vpc("href_remote"), ERR, r"remote tile https://example\.com/tile\.laz is not supported"),
    Case("vpc-tile-fifo", vpc("href_fifo"), ERR, r"tile pipe\.laz is not a regular file"),
    Case("vpc-tile-is-a-vpc", vpc("href_self"), ERR, r"tile list\.vpc is not a LAS/LAZ file"),
    Case("vpc-nested", vpc("nested"), ERR, r"nested\.vpc: not a readable virtual point cloud \(nested too deeply\)"),
    Case("vpc-binary", vpc("binary"), ERR, r"binary\.vpc: not a readable virtual point cloud"),
    Case("vpc-on-tiles-box-wrong", vpc("box_shifted", *TILED), ERR, r"does not match the header of before_3\.laz"),
    # coverage of the after footprint
    Case(
        "before-gap-under-works",
        est("{in}/before_gap.las", "{in}/after.las"),
        0,
        r"coverage: both surveys cover \d+\.\d% .*the before survey misses",
        verdict("not reliable", "the before survey does not cover"),
    ),
    Case(
        "before-misses-all-works",  # was net 0.0 +- 0.0 "not significant"
        est("{in}/before_no_works.las", "{in}/after.las"),
        0,
        r"coverage: both surveys cover \d+\.\d% of the after footprint \(the before survey misses",
        lambda r: verdict("not reliable", "does not cover")(r) or never_not_significant(r),
    ),
    Case(
        "before-gap-under-works-tiled",
        est("{in}/before_gap.las", "{in}/after.las", *TILED),
        0,
        r"quality: NOT RELIABLE",
        verdict("not reliable", "the before survey does not cover"),
    ),
    Case(
        "before-ends-mid-site",
        est("{in}/before_half.las", "{in}/after.las"),
        0,
        r"quality: NOT RELIABLE",
        verdict("not reliable", "of the after footprint"),
    ),
    Case(
        "full-coverage-vpc-on-tiles",
        vpc("before", *TILED),
        0,
        r"coverage: both surveys cover 100\.0% of the after footprint",
        lambda r: r["coverage"]["before_missing_m2"] == 0 or pytest.fail(str(r["coverage"])),
    ),
    # zones and stable-ground polygons
    Case("zones-ok", est("--zones", "{in}/zones.geojson"), 0, r"quality: ", zones_flag("outside_grid", False)),
    Case(
        "zones-one-far-away",
        est("--zones", "{in}/zones_partly_far.geojson"),
        0,
        r"quality: USE WITH CAUTION",
        verdict("use with caution", "'far'"),
    ),
    Case("zones-all-far-away", est("--zones", "{in}/zones_far.geojson"), ERR, r"no zone meets the survey's grid"),
    Case(
        "zones-self-intersecting",
        est("--zones", "{in}/zones_bowtie.geojson"),
        0,
        r"quality: ",
        zones_flag("repaired", True),
    ),
    Case(
        "zones-self-intersecting-tiled",
        est("--zones", "{in}/zones_bowtie.geojson", *TILED),
        0,
        r"quality: ",
        zones_flag("repaired", True),
    ),
    Case(
        "zones-one-far-away-tiled",
        est("--zones", "{in}/zones_partly_far.geojson", *TILED),
        0,
        r"quality: USE WITH CAUTION",
        zones_flag("outside_grid", True),
    ),
    Case(
        "zones-declared-lonlat-hold-metres",
        est("--zones", "{in}/zones_declared_lonlat.geojson"),
        ERR,
        r"'pile' cannot be brought from WGS 84 into the survey's",
    ),
    Case("zones-in-another-utm-zone", est("--zones", "{in}/zones_other_utm.geojson"), ERR, r"no zone meets the survey"),
    Case(
        "zones-no-crs-lonlat",
        est("--zones", "{in}/zones_lonlat_nocrs.shp"),
        ERR,
        r"no zone meets the survey's grid \(the file has no CRS",
    ),
    Case("zones-points-only", est("--zones", "{in}/zones_points.geojson"), ERR, r"no polygon features"),
    Case("zones-no-area", est("--zones", "{in}/zones_line.geojson"), ERR, r"'flat' is not a valid polygon and has no"),
    Case("zones-garbage", est("--zones", "{in}/zones_garbage.gpkg"), ERR, r"cannot read polygons from this zones"),
    Case("zones-fifo", est("--zones", "{in}/zones_fifo.geojson"), ERR, r"not a regular file"),
    Case("zones-missing", est("--zones", "{in}/nowhere.gpkg"), ERR, r"nowhere\.gpkg: zones file not found"),
    Case("stable-mask-missing", est("--stable-mask", "{in}/nowhere.gpkg"), ERR, r"--stable-mask file not found"),
    Case("stable-mask-far", est("--stable-mask", "{in}/stable_far.geojson"), ERR, r"--stable-mask file meets"),
    Case(
        "stable-mask-missing-tiled",
        est("--stable-mask", "{in}/nowhere.gpkg", *TILED),
        ERR,
        r"--stable-mask file not found",
    ),
    # other inputs
    Case("before-is-a-folder", est("{in}/folder.laz", "{in}/after.las"), ERR, r"folder\.laz: not a file"),
    Case("copc-not-copc", est("{in}/secrets.laz", "{in}/after.las"), ERR, r"secrets\.laz: not a readable LAS/LAZ"),
    Case(
        "out-is-an-input",
        ("estimate", "{in}/before.las", "{in}/after.las", "--out", "{in}/after.las"),
        ERR,
        r"the output folder is or contains the input",
    ),
    Case(
        "out-holds-the-inputs",
        ("estimate", "{in}/before.las", "{in}/after.las", "--out", "{in}", "--overwrite"),
        ERR,
        r"the output folder is or contains the input",
    ),
]


def _snapshot(folder: Path) -> dict[str, str]:
    """Every entry under ``folder`` with the digest of regular files (inputs are never written)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        kind = "f" if p.is_file() and not p.is_symlink() else "fifo" if p.is_fifo() else "d"
        out[str(p.relative_to(folder))] = hashlib.md5(p.read_bytes()).hexdigest() if kind == "f" else kind
        assert st.st_mode  # listed
    return out


def _run(args: list[str], cwd: Path, timeout: float = LIMIT_S, interrupt: tuple[str, int] | None = None):
    """(exit code, stdout, stderr, seconds, process group) of ``python -m soilvolume args`` in
    ``cwd`` (a session of its own, its temporary folder ``cwd/tmp``); with ``interrupt`` =
    (regex, signal), the signal goes to its process group, as a terminal's Ctrl-C does, when a
    line of stderr matches; killed (code -9) after ``timeout``."""
    import threading

    env = {**os.environ, "TMPDIR": str(cwd / "tmp")}
    (cwd / "tmp").mkdir(exist_ok=True)
    t0 = time.monotonic()
    p = subprocess.Popen(
        [sys.executable, "-m", "soilvolume", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    err: list[str] = []
    out: list[str] = []

    def read_err() -> None:
        sent = interrupt is None
        for line in p.stderr:
            err.append(line)
            if not sent and re.search(interrupt[0], line):
                os.killpg(p.pid, interrupt[1])
                sent = True

    readers = [
        threading.Thread(target=read_err, daemon=True),
        threading.Thread(target=lambda: out.extend(p.stdout), daemon=True),
    ]
    for r in readers:
        r.start()
    try:
        p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    seconds = time.monotonic() - t0
    for r in readers:
        r.join(5)
    return p.returncode, "".join(out), "".join(err), seconds, p.pid


def group_alive(pgid: int) -> bool:
    """Whether any process of the process group ``pgid`` is still running (zombies aside)."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        state, _, group = stat[stat.rindex(")") + 2 :].split()[:3]
        if int(group) == pgid and state != "Z":
            return True
    return False


def _gone(pgid: int, within: float = 15.0) -> bool:
    end = time.monotonic() + within
    while group_alive(pgid):
        if time.monotonic() > end:
            return False
        time.sleep(0.2)
    return True


LOCAL_TILES = ("--scheduler", "local:2", "--volume-step", "tiles", "--tile-cells", "16")
MOMENTS = [  # (id, the progress line the signal follows, signal)
    ("cluster-starting", r"thinning for registration", signal.SIGINT),
    ("first-pass", r"scanned 1/", signal.SIGINT),
    ("registering", r"registering the after cloud", signal.SIGINT),
    ("gridding", r"gridded tile 1/", signal.SIGINT),
    ("volume-tiles", r"volumes of tile 1/", signal.SIGINT),
    ("sigterm-gridding", r"gridded tile 1/", signal.SIGTERM),
]


def _vpc_run(out: str, *extra: str, inputs: str = "in") -> list[str]:
    return ["estimate", f"{inputs}/before.vpc", f"{inputs}/after.vpc", "--out", out, *LOCAL_TILES, *extra]


def _report(folder: Path, out: str) -> dict:
    path = folder / out / "report.json"
    return json.loads(path.read_text()) if path.exists() else {}


def resume_scenario(inputs: Path, folder: Path) -> dict:
    """An interrupted run resumed unchanged, and one resumed after a tile of its input was
    edited, each against a clean run of the same inputs (on threads: the scheduler does not
    key the tiles)."""
    import shutil

    import laspy

    for name in ("before", "after"):
        shutil.copytree(inputs / name, folder / "in" / name)
        shutil.copyfile(inputs / f"{name}.vpc", folder / "in" / f"{name}.vpc")
    precise = ("--georeferencing", "precise")
    runs = {"r1": _run(_vpc_run("out", *precise), folder, interrupt=(r"gridded tile 2/", signal.SIGINT))}
    runs["r2"] = _run(_vpc_run("out", *precise), folder)
    runs["c1"] = _run(_vpc_run("clean1", *precise, "--quiet", "--scheduler", "threads:2"), folder)
    runs["r3"] = _run(_vpc_run("out2", *precise), folder, interrupt=(r"gridded tile 2/", signal.SIGINT))
    tile = folder / "in" / "after" / "after_1.laz"
    las = laspy.read(tile)
    las.z = las.z + 0.5  # the works' tile raised by half a metre
    las.write(tile)
    runs["r4"] = _run(_vpc_run("out2", *precise), folder)
    runs["c2"] = _run(_vpc_run("clean2", *precise, "--quiet", "--scheduler", "threads:2"), folder)
    reports = {
        k: _report(folder, out) for k, out in (("r2", "out"), ("c1", "clean1"), ("r4", "out2"), ("c2", "clean2"))
    }
    return {"runs": runs, "reports": reports, "folder": folder}


def interrupt_scenario(inputs: Path, folder: Path, when: str, sig: int) -> dict:
    run = _run(_vpc_run("out", inputs=str(inputs)), folder, interrupt=(when, sig))
    return {"run": run, "gone": _gone(run[4]), "folder": folder}


def two_runs_scenario(inputs: Path, folder: Path) -> dict:
    """Two tiled runs started together into one --out."""
    with ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda _: _run(_vpc_run("out", "--quiet", inputs=str(inputs)), folder), range(2)))
    return {"runs": runs, "folder": folder}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """The inputs, the servers, and every case of the table started (``PARALLEL`` at a time)."""
    inputs = write_inputs(tmp_path_factory.mktemp("corpus_in"))
    snapshot = _snapshot(inputs)
    silent, garbage = Server(garbage=False), Server(garbage=True)
    idle_dir = tmp_path_factory.mktemp("idle_scheduler")
    idle = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0"]
        + ["--no-dashboard", "--scheduler-file", str(idle_dir / "s.json")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        cwd=idle_dir,
    )
    for _ in range(300):
        if (idle_dir / "s.json").exists() and json.loads((idle_dir / "s.json").read_text() or "{}").get("address"):
            break
        time.sleep(0.1)
    names = {
        "in": str(inputs),
        "silent": silent.port,
        "garbage": garbage.port,
        "closed": free_port(),
        "idle": json.loads((idle_dir / "s.json").read_text())["address"],
    }
    root = tmp_path_factory.mktemp("corpus_cases")

    def launch(case: Case):
        folder = root / case.id
        folder.mkdir()
        args = [a.format(out=folder / "out", **names) for a in case.args]
        return (*_run(args, folder)[:4], folder)

    def scenario(name: str, fn, *args):
        folder = root / name
        (folder / "in").mkdir(parents=True)
        return fn(inputs, folder, *args)

    waiting = [c for c in CASES if c.waits]
    with ThreadPoolExecutor(PARALLEL) as pool, ThreadPoolExecutor(len(waiting)) as side:
        futures = {c.id: side.submit(launch, c) for c in waiting}
        futures["resume"] = pool.submit(scenario, "resume", resume_scenario)
        futures["two-runs"] = pool.submit(scenario, "two-runs", two_runs_scenario)
        for name, when, sig in MOMENTS:
            futures[name] = pool.submit(scenario, name, interrupt_scenario, when, sig)
        futures.update({c.id: pool.submit(launch, c) for c in CASES if not c.waits})
        yield {"inputs": inputs, "snapshot": snapshot, "futures": futures}
        for f in futures.values():
            f.cancel()
    silent.close()
    garbage.close()
    idle.kill()
    idle.wait()


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_case(corpus, case: Case):
    code, out, err, seconds, folder = corpus["futures"][case.id].result()
    lines = err.strip().splitlines()
    assert seconds <= LIMIT_S, f"took {seconds:.0f} s"
    assert code == case.code, (code, lines[-5:])
    if code != 0:
        assert len(lines) == 1 and lines[0].startswith("soilvolume: error: "), lines
        assert re.search(case.line, lines[0]), lines[0]
        assert "root:" not in lines[0]  # never a file's content
        assert not (folder / "out").exists()
    else:
        assert not lines, lines
        assert re.search(case.line, out, re.M), out
        if case.report:
            case.report(json.loads((folder / "out" / "report.json").read_text()))
    assert sorted(p.name for p in folder.iterdir()) == (["out", "tmp"] if code == 0 else ["tmp"])
    assert not list((folder / "tmp").iterdir()), "temporary files left behind"
    assert _snapshot(corpus["inputs"]) == corpus["snapshot"], "an input changed"


def _leftovers(folder: Path, allowed: set[str]) -> None:
    assert {p.name for p in folder.iterdir()} <= allowed | {"tmp", "in"}, sorted(p.name for p in folder.iterdir())
    assert not list((folder / "tmp").iterdir()), "temporary files left behind"


def _same_volumes(a: dict, b: dict) -> None:
    for key in ("volume_m3", "volume_all_cells_m3", "uncertainty_m3"):
        for part in ("net", "cut", "fill"):
            assert a[key][part] == pytest.approx(b[key][part], rel=1e-9, abs=1e-9), (key, part)


def test_a_resumed_run_after_an_input_changed_equals_a_clean_run(corpus):
    """Interrupted (Ctrl-C: 130, the kept tiles named), resumed unchanged (the kept tiles used:
    the clean run's numbers), interrupted again, a tile raised by 0.5 m, run again: the kept
    tiles discarded with one line saying why, the clean run's numbers of the edited input."""
    got = corpus["futures"]["resume"].result()
    runs, reports = got["runs"], got["reports"]
    for key in ("r1", "r3"):
        code, _, err, seconds, _ = runs[key]
        assert code == 130 and seconds <= LIMIT_S, err[-300:]
        assert re.search(r"finished tiles are kept in .*\.out2?\.soilvolume-tiles for the same", err.splitlines()[-1])
    for key in ("r2", "r4", "c1", "c2"):
        assert runs[key][0] == 0 and runs[key][3] <= LIMIT_S, runs[key][2][-500:]
    assert re.search(r"resuming: \d+ of \d+ tiles done in an earlier run", runs["r2"][2])
    assert reports["r2"]["engine"]["tiles_resumed"] > 0 and not reports["r2"]["engine"]["kept_tiles_discarded"]
    _same_volumes(reports["r2"], reports["c1"])
    said = "discarding the tiles kept by an interrupted run: after_1.laz changed (size, modification time or content)"
    assert said in runs["r4"][2] and reports["r4"]["engine"]["tiles_resumed"] == 0
    _same_volumes(reports["r4"], reports["c2"])
    assert reports["c2"]["volume_m3"]["net"] > reports["c1"]["volume_m3"]["net"] + 100  # the edit mattered
    _leftovers(got["folder"], {"out", "out2", "clean1", "clean2"})
    assert _snapshot(corpus["inputs"]) == corpus["snapshot"]


@pytest.mark.parametrize(("name", "when", "sig"), MOMENTS, ids=[m[0] for m in MOMENTS])
def test_a_signal_to_a_local_cluster_run(corpus, name, when, sig):
    """SIGINT to the process group (a terminal's Ctrl-C: the workers get it too) or SIGTERM, at
    each step of a LocalCluster run: 130/143 and one line after the progress, the workers gone
    within 15 s, nothing left but the kept tiles (only once some were gridded)."""
    got = corpus["futures"][name].result()
    code, _, err, seconds, _ = got["run"]
    lines = err.strip().splitlines()
    assert code == 128 + sig and seconds <= LIMIT_S, lines[-5:]
    stray = [line for line in lines[:-1] if not line.startswith("[")]  # shown whole when there are any
    assert not stray, stray
    assert re.fullmatch(
        rf"soilvolume: error: interrupted by {signal.Signals(sig).name}; nothing was written.*", lines[-1]
    )
    assert got["gone"], "worker processes left running"
    kept = got["folder"] / ".out.soilvolume-tiles"
    assert ("kept in" in lines[-1]) == kept.exists()
    if kept.exists():
        assert {p.suffix for p in kept.iterdir()} <= {".npy", ".json"}, sorted(kept.iterdir())
    _leftovers(got["folder"], {".out.soilvolume-tiles"})
    assert _snapshot(corpus["inputs"]) == corpus["snapshot"]


def test_two_tiled_runs_into_one_out_both_end_cleanly(corpus):
    """Each run has its own tile store and temporary names: both end, one may refuse in one
    line; no Dask dashboard or port warnings."""
    got = corpus["futures"]["two-runs"].result()
    codes = sorted(r[0] for r in got["runs"])
    assert codes in ([0, 0], [0, 1]), [r[2][-300:] for r in got["runs"]]
    for code, _, err, seconds, _ in got["runs"]:
        assert seconds <= LIMIT_S
        lines = err.strip().splitlines()
        assert lines == [] if code == 0 else (len(lines) == 1 and "another run" in lines[0]), lines
    assert (got["folder"] / "out" / "report.json").exists()
    _leftovers(got["folder"], {"out"})
