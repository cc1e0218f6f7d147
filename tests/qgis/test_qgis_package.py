"""The zip from scripts/package.sh installs into an empty plugins folder and loads."""

from __future__ import annotations

import configparser
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
REQUIRED_METADATA = (
    "name",
    "qgisMinimumVersion",
    "description",
    "about",
    "version",
    "author",
    "email",
    "repository",
    "tracker",
)

LOADER = r"""
import json, sys
from unittest import mock
from qgis.core import QgsApplication

app = QgsApplication([], False)
app.initQgis()
import qgis.utils as utils

plugins_dir = sys.argv[1]
sys.path.insert(0, plugins_dir)
utils.plugin_paths[:] = [plugins_dir]
utils.updateAvailablePlugins()
iface = mock.MagicMock()
iface.mainWindow.return_value = None
utils.iface = iface
out = {"available": list(utils.available_plugins),
       "loaded": utils.loadPlugin("soilvolume_qgis"),
       "started": utils.startPlugin("soilvolume_qgis")}
module = sys.modules["soilvolume_qgis"]
registry = QgsApplication.processingRegistry()
provider = registry.providerById("soilvolume")
out["plugin_file"] = module.__file__
out["algorithms"] = sorted(a.id() for a in provider.algorithms()) if provider else []
out["menu_calls"] = iface.addPluginToMenu.call_count
from soilvolume_qgis.processing import optiontable
out["engine_file"] = optiontable.engine("options").__file__
out["unloaded"] = utils.unloadPlugin("soilvolume_qgis")
out["provider_after_unload"] = registry.providerById("soilvolume") is not None
print("RESULT" + json.dumps(out))
app.exitQgis()
"""


def test_zip_contents(plugin_zip):
    version = configparser.ConfigParser()
    version.read(REPO / "metadata.txt")
    assert plugin_zip.name == f"soilvolume_qgis-{version['general']['version']}.zip"
    names = zipfile.ZipFile(plugin_zip).namelist()
    assert all(n.startswith("soilvolume_qgis/") for n in names)
    for required in (
        "metadata.txt",
        "__init__.py",
        "LICENSE",
        "qgisplugin.py",
        "processing/provider.py",
        "resources/icon.png",
        "resources/icon.svg",
        "resources/styles/difference.qml",
        "resources/styles/dem.qml",
        "soilvolume/api.py",
        "soilvolume/workflow/estimate.py",
        "plugin/engine-lock.txt",
        "plugin/environment.py",
        "plugin/interpreters.py",
        "plugin/platforms.py",
        "soilvolume/native/kernels.h",  # the kernels' sources (native.SOURCES)
        "soilvolume/native/chunks.c",
        "soilvolume/native/cells.c",
        "soilvolume/native/registration.c",
        "soilvolume/native/build.py",
        "soilvolume/reporting/templates/base.html.j2",  # report.html's templates
        "soilvolume/reporting/templates/report.html.j2",
        "soilvolume/reporting/templates/series.html.j2",
    ):
        assert f"soilvolume_qgis/{required}" in names, required
    for banned in ("tests/", ".venv/", "__pycache__", ".pyc", ".git/", "egg-info", "bench/", "_soilvolume_kernels-"):
        assert not any(banned in n for n in names), banned
    # one zip for Linux, Windows and macOS: no compiled file of any one system (the installer builds them)
    assert not [n for n in names if n.lower().endswith((".so", ".pyd", ".dll", ".dylib", ".exe", ".o"))]


def test_metadata_has_every_required_field():
    parser = configparser.ConfigParser()
    parser.read(REPO / "metadata.txt", encoding="utf-8")
    general = parser["general"]
    for key in REQUIRED_METADATA:
        assert general.get(key, "").strip(), key
    assert general["qgisMinimumVersion"] == "3.28"
    assert general["hasProcessingProvider"] == "yes"
    assert (REPO / general["icon"]).is_file()
    engine_init = (REPO / "soilvolume" / "__init__.py").read_text()
    assert f'__version__ = "{general["version"]}"' in engine_init


def test_zip_installs_and_loads(plugin_zip, tmp_path):
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    zipfile.ZipFile(plugin_zip).extractall(plugins)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(QT_QPA_PLATFORM="offscreen", QGIS_CUSTOM_CONFIG_PATH=str(tmp_path / "profile"))
    run = subprocess.run(
        [sys.executable, "-c", LOADER, str(plugins)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    line = next(ln for ln in run.stdout.splitlines() if ln.startswith("RESULT"))
    out = json.loads(line[len("RESULT") :])
    assert out["available"] == ["soilvolume_qgis"]
    assert out["loaded"] and out["started"]
    assert out["plugin_file"].startswith(str(plugins))
    assert out["engine_file"].startswith(str(plugins))  # the engine shipped in the zip
    assert out["algorithms"] == [
        f"soilvolume:{n}"
        for n in (
            "estimatevolumechange",
            "installdependencies",
            "pointcloudtodem",
            "registerpointclouds",
            "stockpilevolumes",
            "volumefromdems",
            "volumeseries",
        )
    ]
    assert out["menu_calls"] == 2  # the estimate and "Install dependencies…"
    assert out["unloaded"] and not out["provider_after_unload"]
