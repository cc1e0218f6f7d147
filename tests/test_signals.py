"""SIGINT/SIGTERM at several moments of a real run (estimate, series, tiles on a Dask cluster or
threads): exit 130/143 with one line, no traceback, no segfault, nothing left behind, no worker
left running; a worker killed mid-run is one line and nothing written; a SIGKILLed run's staging
folder is removed by the next run.

The signal is sent when the stage's progress line appears (``--progress jsonl``), on a pair large
enough (1 M points) that the run is still in that stage: an interrupt test that lets the run
finish first tests nothing (with 100 k points and a delay after the line, SIGINT and SIGTERM
during the registration landed after the commit on 3 of 3 tries and exit 0 was accepted)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import run_cli, run_python, write_scene
from processes import group_alive

from soilvolume.scenes.series import write_series

TILES = ("--tile-cells", "32")  # 16 tiles: the run is still gridding after the first


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    before, after, _ = write_scene(tmp_path_factory.mktemp("signals"), 0, before_points=600_000, after_points=400_000)
    return before, after


@pytest.fixture(scope="module")
def surveys(tmp_path_factory):
    paths, _ = write_series(tmp_path_factory.mktemp("series") / "scene", seed=0)
    return paths


def _start(args, out: Path, env: dict | None = None) -> subprocess.Popen:
    """The command in a session of its own (its workers in its process group), its events on stdout."""
    return subprocess.Popen(
        [sys.executable, "-m", "soilvolume", *map(str, args), "--out", str(out), "--progress", "jsonl"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=None if env is None else {**os.environ, **env},
    )


def _wait_for(proc: subprocess.Popen, text: str) -> list[dict]:
    """The events up to the first progress line containing ``text``; fails if the run ends first."""
    events = []
    for line in proc.stdout:
        events.append(json.loads(line))
        if events[-1]["type"] == "progress" and text in events[-1]["message"]:
            return events
    pytest.fail(f"the run ended before {text!r}: {events[-3:]}, {proc.stderr.read()[-2000:]}")


def _finish(proc: subprocess.Popen) -> tuple[int, list[dict], list[str]]:
    """(exit status, the remaining events, stderr's lines) once the run ended."""
    events = [json.loads(line) for line in proc.stdout]
    err = proc.stderr.read().splitlines()
    return proc.wait(timeout=120), events, err


def _gone(pgid: int, grace_s: float = 5.0) -> list[str]:
    """The command lines of the process group's processes still alive ``grace_s`` after the run
    ended (a worker's own exit follows its driver's by a moment)."""
    end = time.monotonic() + grace_s
    while (alive := group_alive(pgid)) and time.monotonic() < end:
        time.sleep(0.1)
    return [_cmdline(pid) for pid in alive]


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:200]
    except OSError:
        return f"{pid} (gone)"


def _interrupted(proc: subprocess.Popen, sig: signal.Signals, out: Path, tiles: bool = False) -> None:
    """Sends ``sig`` now; the run must stop with 128 + sig, one line, nothing left (but the
    finished tiles of a tiled run, kept to resume), no process left."""
    proc.send_signal(sig)
    code, events, err = _finish(proc)
    assert code == 128 + sig, (code, events[-3:], err[-5:])
    said = f"soilvolume: error: interrupted by {sig.name}; nothing was written"
    kept = out.parent / f".{out.name}.soilvolume-tiles"
    if tiles:
        said += f" to the output folder; finished tiles are kept in {kept} for the same command to resume"
    assert err == [said], err
    assert events[-1]["type"] == "error" and sig.name in events[-1]["message"], events[-1]
    assert sorted(p.name for p in out.parent.iterdir()) == ([kept.name] if tiles else []), "files left behind"
    assert _gone(proc.pid) == [], "a worker outlived the run"


@pytest.mark.parametrize(
    ("sig", "stage"),
    [
        (signal.SIGINT, "reading"),
        (signal.SIGINT, "registering"),
        (signal.SIGTERM, "registering"),
        (signal.SIGTERM, "gridding"),
        (signal.SIGINT, "computing the difference"),
        (signal.SIGTERM, "writing outputs"),
    ],
)
def test_signal_cleans_up_and_exits(pair, tmp_path, sig, stage):
    out = tmp_path / "result"
    proc = _start(["estimate", *pair], out)
    _wait_for(proc, stage)
    _interrupted(proc, sig, out)


@pytest.mark.parametrize(("sig", "stage"), [(signal.SIGINT, "registering"), (signal.SIGTERM, "period")])
def test_signal_stops_a_series(surveys, tmp_path, sig, stage):
    out = tmp_path / "site"
    proc = _start(["series", *surveys], out)
    _wait_for(proc, stage)
    _interrupted(proc, sig, out)


@pytest.mark.parametrize(
    ("sig", "scheduler"), [(signal.SIGINT, "local:2"), (signal.SIGTERM, "local:2"), (signal.SIGTERM, "threads:2")]
)
def test_signal_stops_tiles_on_a_dask_cluster_or_threads(pair, tmp_path, sig, scheduler):
    """Mid-tiles: the cluster and its worker processes go with the run; the tiles finished are
    kept beside the output folder for the same command to resume."""
    out = tmp_path / "result"
    proc = _start(["estimate", *pair, "--scheduler", scheduler, *TILES], out)
    _wait_for(proc, "gridded tile 1/")
    _interrupted(proc, sig, out, tiles=True)


def test_a_worker_killed_mid_run_is_one_line_and_nothing_written(pair, tmp_path):
    """Both workers of a local:2 cluster SIGKILLed mid-tiles (as the kernel's OOM killer does):
    the data sent to them dies with them and Dask cancels the tasks needing it. It was said as
    "the Dask cluster stopped the run's tasks while gridded tiles (FuturesCancelledError)"; now
    the line says the workers died and what to change."""
    out = tmp_path / "result"
    proc = _start(["estimate", *pair, "--scheduler", "local:2", *TILES], out)
    _wait_for(proc, "gridded tile 1/")
    workers = [pid for pid in group_alive(proc.pid) if pid != proc.pid and _parent(pid) != proc.pid]
    assert len(workers) == 2, workers  # the run's children: the forkserver and its resource tracker
    for pid in workers:
        os.kill(pid, signal.SIGKILL)
    code, events, err = _finish(proc)
    assert code == 1, (code, err)
    assert err == [
        "soilvolume: error: 2 of the 2 Dask workers died while the tiles were being gridded (killed, or out of "
        "memory? give each worker more with --memory-limit, or smaller tiles with --tile-cells)"
    ], err
    assert events[-1]["type"] == "error"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    assert _gone(proc.pid) == []


def test_a_worker_killed_mid_run_leaves_the_other_to_finish_the_same_volumes(pair, tmp_path):
    """One of the two local:2 workers SIGKILLed mid-tiles: its tasks go to the other (the data
    was sent to both) and the run gives the volumes of an undisturbed run."""
    out = tmp_path / "result"
    proc = _start(["estimate", *pair, "--scheduler", "local:2", *TILES], out)
    _wait_for(proc, "gridded tile 1/")
    workers = [pid for pid in group_alive(proc.pid) if pid != proc.pid and _parent(pid) != proc.pid]
    os.kill(workers[0], signal.SIGKILL)
    code, events, err = _finish(proc)
    assert code == 0 and events[-1]["type"] == "result", (code, err[-5:])
    done = run_cli("estimate", *pair, "--scheduler", "threads:2", *TILES, "--out", tmp_path / "undisturbed", "--quiet")
    assert done.returncode == 0, done.stderr
    undisturbed = json.loads((tmp_path / "undisturbed" / "report.json").read_text())["volume_m3"]
    volumes = json.loads((out / "report.json").read_text())["volume_m3"]
    assert {k: volumes[k] for k in ("net", "cut", "fill")} == pytest.approx(
        {k: undisturbed[k] for k in ("net", "cut", "fill")}, rel=1e-9
    )
    assert _gone(proc.pid) == []


def _leftovers(out: Path) -> list[str]:
    return [p.name for p in out.parent.iterdir() if "soilvolume-" in p.name]


def _parent(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except OSError:
        return 0


def test_killed_run_leftovers_are_removed_by_the_next_run(pair, tmp_path):
    out = tmp_path / "result"
    proc = _start(["estimate", *pair], out)
    _wait_for(proc, "registering")
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert _leftovers(out), "the killed run should have left its staging folder"
    p = run_cli("estimate", *pair, "--out", out, "--quiet")
    assert p.returncode == 0, p.stderr
    assert _leftovers(out) == []
    assert (out / "report.json").exists()


def test_a_kill_between_the_two_renames_of_a_swap_restores_the_old_set(tmp_path):
    from soilvolume.core.outputs import TRASH, sibling, sweep

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    ).stdout.strip()
    out = tmp_path / "result"
    trash = sibling(out, TRASH, int(dead), token="ab12")
    trash.mkdir()
    (trash / "report.json").write_text("{}")
    staged = sibling(out, "soilvolume-staging", int(dead), token="ab12")
    staged.mkdir()
    sweep(out)
    assert sorted(os.listdir(tmp_path)) == ["result"]
    assert (out / "report.json").read_text() == "{}"


def test_signal_after_the_run_is_ignored_on_the_way_out():
    """A signal between the last write and the exit status must not turn a success into -2."""
    script = (
        "import os, signal\n"
        "from soilvolume.core.interrupt import handle_signals\n"
        "with handle_signals(then_ignore=True):\n"
        "    pass\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "print('exited normally')\n"
    )
    done = run_python(script)
    assert (done.returncode, done.stdout.strip()) == (0, "exited normally"), done.stderr
