"""Headless runs through the ``qgis_process`` command line, in a throw-away QGIS profile."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

QGIS_PROCESS = shutil.which("qgis_process")
pytestmark = pytest.mark.skipif(QGIS_PROCESS is None, reason="qgis_process is not installed")


@pytest.fixture(scope="module")
def qgis_env(plugins_dir, tmp_path_factory) -> dict[str, str]:
    """Environment of a headless qgis_process with only this plugin enabled, in a temp profile;
    a stock QGIS Python (nothing of the dev venv), the engine in the environment make setup built."""
    config = tmp_path_factory.mktemp("qgis-profile")
    env = dict(os.environ)
    env.update(
        QT_QPA_PLATFORM="offscreen",
        QGIS_PLUGINPATH=str(plugins_dir),
        QGIS_CUSTOM_CONFIG_PATH=str(config),
    )
    for key in ("QGIS_OPTIONS_PATH", "PYTHONPATH", "VIRTUAL_ENV"):  # pytest-qgis's settings, the venv
        env.pop(key, None)  # pytest-qgis points it at its own settings
    run = subprocess.run(
        [QGIS_PROCESS, "plugins", "enable", "soilvolume_qgis"], env=env, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return env


def qgis_process(env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([QGIS_PROCESS, *args], env=env, capture_output=True, text=True, timeout=300)


def test_qgis_process_lists_the_algorithms(qgis_env):
    run = qgis_process(qgis_env, "list")
    assert run.returncode == 0, run.stderr
    for name in (
        "estimatevolumechange",
        "pointcloudtodem",
        "registerpointclouds",
        "volumefromdems",
        "installdependencies",
    ):
        assert f"soilvolume:{name}" in run.stdout


def test_qgis_process_runs_the_pipeline(qgis_env, scene_dir, truth, tmp_path):
    run = qgis_process(
        qgis_env,
        "run",
        "soilvolume:estimatevolumechange",
        "--json",
        "--",
        f"BEFORE={scene_dir / 'before.las'}",
        f"AFTER={scene_dir / 'after.las'}",
        "CELL=1",
        f"DIFFERENCE={tmp_path / 'difference.tif'}",
        f"DEM_BEFORE={tmp_path / 'dem_before.tif'}",
        f"REPORT_JSON={tmp_path / 'report.json'}",
    )
    assert run.returncode == 0, run.stderr + run.stdout
    results = json.loads(run.stdout)["results"]
    # measured -0.58 % net, -2.4 % cut, -0.71 % fill (it was 3 % on the net, cut and fill unchecked)
    assert results["NET_VOLUME"] == pytest.approx(truth["net"], rel=0.015)
    assert results["CUT_VOLUME"] == pytest.approx(truth["cut"], rel=0.06)
    assert results["FILL_VOLUME"] == pytest.approx(truth["fill"], rel=0.02)
    assert isinstance(results["UNCOMPENSATED_NET_VOLUME"], float)
    assert Path(results["DIFFERENCE"]).is_file() and Path(results["DEM_BEFORE"]).is_file()
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["volume_m3"]["net"] == pytest.approx(results["NET_VOLUME"])


def test_qgis_process_without_the_environment_explains_the_fix(qgis_env, scene_dir, tmp_path):
    env = dict(qgis_env, SOILVOLUME_ENGINE_ENV=str(tmp_path / "none"))
    listed = qgis_process(env, "list")
    assert "soilvolume:estimatevolumechange" in listed.stdout  # the plugin still loads
    run = qgis_process(
        env,
        "run",
        "soilvolume:estimatevolumechange",
        "--",
        f"BEFORE={scene_dir / 'before.las'}",
        f"AFTER={scene_dir / 'after.las'}",
        f"DIFFERENCE={tmp_path / 'difference.tif'}",
    )
    assert run.returncode != 0
    output = run.stdout + run.stderr
    assert output.count("not installed yet") == 1, output  # the advice once, not once per printer
    assert "qgis_process run soilvolume:installdependencies" in output
    assert "Traceback" not in output and not (tmp_path / "difference.tif").exists()
