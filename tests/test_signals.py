"""SIGINT/SIGTERM at several moments of a real run: exit 130/143 with one line, no traceback, no
segfault, nothing left behind; a SIGKILLed run's staging folder is removed by the next run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import run_cli, run_python, write_scene

PROGRESS = "["


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    before, after, _ = write_scene(tmp_path_factory.mktemp("signals"), 0)
    return before, after


def _start(pair, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "soilvolume", "estimate", *map(str, pair), "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(proc: subprocess.Popen, text: str) -> list[str]:
    """stderr lines up to the first progress line containing ``text``."""
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if text in line:
            return lines
    return lines


def _leftovers(out: Path) -> list[str]:
    return [p.name for p in out.parent.iterdir() if "soilvolume-" in p.name]


@pytest.mark.parametrize(
    ("sig", "stage", "delay"),
    [
        (signal.SIGINT, "reading", 0.0),
        (signal.SIGINT, "registering", 0.3),  # during the late Open3D import / registration
        (signal.SIGINT, "registering", 1.5),
        (signal.SIGTERM, "registering", 0.8),
        (signal.SIGTERM, "gridding", 0.0),
        (signal.SIGINT, "writing outputs", 0.0),
    ],
)
def test_signal_cleans_up_and_exits(pair, tmp_path, sig, stage, delay):
    out = tmp_path / "result"
    proc = _start(pair, out)
    before = _wait_for(proc, stage)
    time.sleep(delay)
    proc.send_signal(sig)
    rest = proc.stderr.read()
    code = proc.wait(timeout=120)
    errors = [ln for ln in rest.splitlines() if not ln.startswith(PROGRESS)]
    assert code in (0, 128 + sig), (code, before, rest)  # 0: the run had committed already
    if code == 0:
        assert (out / "report.json").exists()
    else:
        assert errors == [f"soilvolume: error: interrupted by {signal.Signals(sig).name}; nothing was written"], rest
        assert not out.exists()
    assert _leftovers(out) == []


def test_killed_run_leftovers_are_removed_by_the_next_run(pair, tmp_path):
    out = tmp_path / "result"
    proc = _start(pair, out)
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
