"""A QGIS test session leaves no plugin link folder behind, and removes those of killed sessions."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
LINK_PREFIX = "soilvolume-qgis-plugins-"  # conftest.LINK_PREFIX


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_session_removes_its_link_folder_and_stale_ones(tmp_path):
    stale = tmp_path / f"{LINK_PREFIX}{dead_pid()}-abc"
    live = tmp_path / f"{LINK_PREFIX}{os.getpid()}-abc"
    for folder in (stale, live):
        folder.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp_path), "QT_QPA_PLATFORM": "offscreen"}
    test = "tests/qgis/test_qgis_provider.py"
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", test],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    left = sorted(p.name for p in Path(tmp_path).glob(f"{LINK_PREFIX}*"))
    assert left == [live.name]  # its own folder gone, the dead session's too, a live one kept
