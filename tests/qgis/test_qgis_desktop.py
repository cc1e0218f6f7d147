"""The QGIS desktop itself (``/usr/bin/qgis`` under Xvfb), as a new analyst meets the plugin: the
zip installed into a clean profile, the message bar's Install button clicked (a real install from
PyPI into the profile), then QGIS's Batch dialog with three rows (Autzen, Tommy Thompson, Autzen
again; the HTML report asked for, the DEM columns blank), results loaded (``desktop_session.py``
runs inside QGIS with ``--code``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
import zipfile
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REAL = (
    Path("/work/shared/data/real") if Path("/work/shared/data/real").is_dir() else HERE.parents[2] / "shared/data/real"
)
QGIS = shutil.which("qgis")
PAIRS = (
    ("autzen_bmx_2010.las", "autzen_bmx_2023.las"),
    ("tommy_thompson_park_2015.laz", "tommy_thompson_park_2023.laz"),
    ("autzen_bmx_2010.las", "autzen_bmx_2023.las"),
)
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(QGIS is None or shutil.which("xvfb-run") is None, reason="needs QGIS's desktop and xvfb-run"),
    pytest.mark.skipif(not (REAL / "autzen_bmx_2010.las").is_file(), reason="real data not present"),
]


@pytest.fixture(scope="module")
def desktop(plugin_zip, tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("desktop")
    plugins = root / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    zipfile.ZipFile(plugin_zip).extractall(plugins)
    settings = root / "profiles" / "default" / "QGIS" / "QGIS3.ini"
    settings.parent.mkdir(parents=True)
    settings.write_text("[PythonPlugins]\nsoilvolume_qgis=true\n", encoding="utf-8")
    (root / "out").mkdir()
    (root / "home").mkdir()
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("PYTHON", "SOILVOLUME_", "QGIS_", "QT_", "VIRTUAL_ENV"))
    }
    env.update(
        HOME=str(root / "home"),
        SOILVOLUME_DESKTOP_OUT=str(root / "out"),
        SOILVOLUME_DESKTOP_PAIRS=";".join(",".join(str(REAL / name) for name in pair) for pair in PAIRS),
    )
    command = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", QGIS, "--profiles-path", str(root)]
    command += ["--nologo", "--noversioncheck", "--code", str(HERE / "desktop_session.py")]
    t0 = time.time()
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=2400, cwd=str(root))
    summary_file = root / "out" / "summary.json"
    assert summary_file.is_file(), done.stderr[-3000:] + (root / "out" / "progress.log").read_text()[-3000:]
    summary = json.loads(summary_file.read_text())
    print(f"QGIS desktop session: {time.time() - t0:.0f} s, install {summary['install'].get('seconds', 0):.0f} s")
    return {"summary": summary, "root": root, "returncode": done.returncode}


def test_install_from_the_bar_says_installed(desktop):
    summary = desktop["summary"]
    assert summary["plugin_loaded"] and "failure" not in summary, summary.get("failure")
    install = summary["install"]
    assert install["clicked"], install  # a clean profile: the bar offers the install
    ours = [m for m in install["messages"] if m["title"] == "Soil volume change"]
    assert any(m["text"] == "Installed and tested: the algorithms are ready." for m in ours), ours
    assert not [m for m in ours if m["level"] == 2], ours  # no Critical
    assert summary["python_errors"] == [], summary["python_errors"]


def test_batch_of_three_rows_without_red_errors(desktop):
    batch = desktop["summary"]["batch"]
    assert batch["reports"] == [True, True, True], batch
    assert batch["not_generated"] == 0 and batch["red"] == 0, batch["log_tail"]
    assert desktop["summary"]["python_errors"] == []


def test_three_groups_with_the_polygons_on_top(desktop):
    tree = desktop["summary"]["tree"]
    assert tree["root_layers"] == [] and len(tree["groups"]) == 3, tree
    for name, layers in tree["groups"].items():
        assert " (run " in name, name
        assert [layer.split(" (")[0] for layer in layers] == ["Areas of significant change", "Difference"], tree
    assert all(s["fill_alpha"] <= 64 and s["outline_alpha"] == 255 for s in tree["symbols"]), tree["symbols"]
