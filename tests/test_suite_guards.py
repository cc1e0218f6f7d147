"""The suite's own guards: a hung test fails after the configured timeout (and the run goes on)
instead of eating CI's 90 minutes, and no test file turns a renamed project module into a skip."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OWN = ("soilvolume", "soilvolume_qgis", "plugin", "processing")

HANG = """
import subprocess


def test_a_stuck_child():
    subprocess.run(["sleep", "1000"])  # a child that never answers


def test_the_next_one():
    assert True
"""


def test_the_suite_has_a_generous_per_test_timeout():
    """pytest-timeout from the dev dependencies, its limit in pytest's configuration: minutes,
    far under CI's 90 (the slowest test takes about 2 minutes on 2 loaded cores)."""
    text = (ROOT / "pyproject.toml").read_text()
    dev = re.search(r"^dev = \[(.*)\]", text, re.M).group(1)
    assert '"pytest-timeout"' in dev, dev
    assert 300 <= int(re.search(r"^timeout = (\d+)$", text, re.M).group(1)) <= 1200
    import pytest_timeout  # noqa: F401 - installed, so the limit applies


def test_a_hung_test_is_stopped_and_the_run_goes_on(tmp_path):
    """The repository's pytest configuration with the limit lowered to 3 s: the stuck test fails
    naming the timeout, its child is killed, the next test passes. Without the plugin
    (``-p no:timeout``) the same file hangs until the outer 60 s limit kills it."""
    test = tmp_path / "test_hang.py"
    test.write_text(HANG)
    plugins = ["-p", "no:cacheprovider", "-p", "no:pytest_qgis", "-p", "no:dash"]  # QGIS and Dash: seconds to load
    args = [sys.executable, "-m", "pytest", "-q", *plugins, "-c", str(ROOT / "pyproject.toml")]
    t0 = time.perf_counter()
    done = subprocess.run(
        [*args, "--rootdir", str(tmp_path), "-o", "timeout=3", str(test)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    seconds = time.perf_counter() - t0
    assert done.returncode == 1, done.stdout[-2000:]
    assert "Failed: Timeout (>3.0s) from pytest-timeout" in done.stdout, done.stdout[-2000:]
    assert "1 failed, 1 passed" in done.stdout, done.stdout[-2000:]
    assert seconds < 50, seconds


def _importorskips(path: Path) -> list[str]:
    """The module names a test file passes to ``pytest.importorskip``."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "importorskip" and node.args:
            arg = node.args[0]
            names.append(arg.value if isinstance(arg, ast.Constant) else ast.unparse(arg))
    return names


def test_no_test_skips_on_a_missing_project_module():
    """A renamed or removed module of the project must fail its tests, not skip them: only
    third-party modules may be import-or-skipped."""
    found = {
        str(path.relative_to(ROOT)): name
        for path in sorted((ROOT / "tests").rglob("*.py"))
        for name in _importorskips(path)
        if name.split(".")[0] in OWN
    }
    assert found == {}, found
