"""The installer's fallbacks, run for real on this machine's Python with what it offers
overridden: a stock QGIS may lack ``ensurepip`` (Debian's python3-venv), pip (python3-pip) and
even ``venv``. Each path installs the lock, self-tests the engine and writes its stamp; the
engine then runs isolated from the system's packages (Debian's pyproj 3.4.1 is not seen)."""

from __future__ import annotations

import json
import subprocess

import pytest

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(
    ("caps", "mode"),
    [
        ({"venv": True, "ensurepip": False, "pip": False}, "venv"),  # venv --without-pip + PyPI's pip wheel
        ({"venv": False, "ensurepip": False, "pip": False}, "target"),  # pip --target + python -I -S
    ],
    ids=["venv-without-ensurepip", "no-venv-no-pip"],
)
def test_fallback_installs_a_working_isolated_engine(plugin_package, tmp_path, caps, mode):
    from soilvolume_qgis.plugin import environment

    lines: list[str] = []
    installer = environment.Installer(
        tmp_path / "engine", log=lines.append, python="/usr/bin/python3", caps=environment.Capabilities((3, 11), **caps)
    )
    env = installer.run()
    assert env.mode == mode and environment.load(tmp_path / "engine") == env
    assert any("downloading pip's wheel from PyPI" in line for line in lines), lines[:20]
    assert any(line.startswith("Self-test passed") for line in lines)
    probe = (
        "import pyproj,sys,json;print(json.dumps([pyproj.__version__, [p for p in sys.path if 'dist-packages' in p]]))"
    )
    run = subprocess.run(env.python(["-c", probe]), capture_output=True, text=True, timeout=120)
    version, system_paths = json.loads(run.stdout)
    assert version == "3.7.2" and system_paths == []  # the lock's pyproj, no system site-packages
    again = []
    environment.Installer(tmp_path / "engine", log=again.append).run()
    assert again == [f"The engine's environment is ready ({tmp_path / 'engine'}); nothing to do."]
