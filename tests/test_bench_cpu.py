"""The benchmark's CPU figure (bench/versus.py, issue 22) counts processes a command leaves to
finish after it: a local Dask cluster's forkserver and the workers it forked are not the
command's waited children."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from conftest import run_python

BENCH = Path(__file__).resolve().parent.parent / "bench"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a subreaper is a Linux feature")
def test_the_cpu_of_an_orphan_the_command_leaves_behind_is_counted(tmp_path):
    burn = (
        "import os, time\n"
        "if os.fork() == 0:\n"
        "    t = time.process_time()\n"
        "    while time.process_time() - t < 1.0: pass\n"
        "os._exit(0)\n"  # the parent at once, the child after 1 s of CPU
    )
    code = (
        f"import json, sys; sys.path.insert(0, {str(BENCH)!r})\n"
        "from pathlib import Path\n"
        "import versus\n"
        "out = {}\n"
        "for reap in (False, True):\n"
        "    versus.SUBREAPER = reap and versus._become_subreaper()\n"
        f"    out[reap] = versus.run([sys.executable, '-c', {burn!r}], Path({str(tmp_path)!r}) / f'{{reap}}.log')\n"
        "print(json.dumps([out[False]['cpu_s'], out[True]['cpu_s'], out[True]['wall_s']]))\n"
    )
    r = run_python(code, timeout=60)
    assert r.returncode == 0, r.stderr
    plain, reaped, wall = json.loads(r.stdout.splitlines()[-1])
    assert plain < 0.5 * reaped  # the command alone: its orphan's CPU is lost
    # counted, but not in the command's wall time (which waiting for the orphan would make at
    # least its 1 s of CPU: relative, so a loaded machine's slow start-up does not fail it)
    assert reaped >= 0.95 and wall < reaped, (plain, reaped, wall)
