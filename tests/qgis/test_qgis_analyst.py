"""The QGIS desktop itself (``/usr/bin/qgis`` under Xvfb) as a new analyst clicks it (issue 49,
items 1, 2, 7 and 10): the plugin enabled in a clean profile with the engine's environment given,
``analyst_session.py`` run inside QGIS with ``--code``."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
QGIS = shutil.which("qgis")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(QGIS is None or shutil.which("xvfb-run") is None, reason="needs QGIS's desktop and xvfb-run"),
]


@pytest.fixture(scope="module")
def desktop(scene_dir, tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("analyst")
    plugins = root / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    (plugins / "soilvolume_qgis").symlink_to(REPO, target_is_directory=True)
    settings = root / "profiles" / "default" / "QGIS" / "QGIS3.ini"
    settings.parent.mkdir(parents=True)
    settings.write_text("[PythonPlugins]\nsoilvolume_qgis=true\n", encoding="utf-8")
    for folder in ("out", "home"):
        (root / folder).mkdir()
    scene = root / "scene"  # a folder of its own: the pickers list what they show of it
    shutil.copytree(scene_dir, scene)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "QGIS_", "QT_", "VIRTUAL_ENV"))}
    env.update(HOME=str(root / "home"), SOILVOLUME_ANALYST_OUT=str(root / "out"), SOILVOLUME_ANALYST_SCENE=str(scene))
    env["SOILVOLUME_ENGINE_ENV"] = os.environ.get("SOILVOLUME_ENGINE_ENV", str(REPO / ".engine-env"))
    command = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", QGIS, "--profiles-path", str(root)]
    command += ["--nologo", "--noversioncheck", "--code", str(HERE / "analyst_session.py")]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=900, cwd=str(root))
    summary_file = root / "out" / "summary.json"
    progress = root / "out" / "progress.log"
    assert summary_file.is_file(), done.stderr[-3000:] + (progress.read_text() if progress.is_file() else "")
    summary = json.loads(summary_file.read_text())
    assert summary.get("plugin_loaded") and "failure" not in summary, summary.get("failure")
    assert summary["python_errors"] == [], summary["python_errors"]
    return {"summary": summary, "stderr": done.stderr, "out": root / "out"}


def test_before_pickers_open_on_point_clouds(desktop):
    """Item 1: the Before "…" of the dialog and of Batch open on the point clouds, so the scene's
    .las files are listed (was: on "DEM GeoTIFF", an empty-looking folder); the design GeoTIFF is
    the next choice."""
    pickers = desktop["summary"]["pickers"]
    for where in ("dialog_BEFORE", "batch_BEFORE", "dialog_AFTER"):
        seen = pickers[where]
        assert seen.get("opens_on", "").startswith("Point clouds ("), (where, seen)
        assert seen["listed"] == ["after.las", "before.las"], (where, seen)
    for where in ("dialog_BEFORE", "batch_BEFORE"):
        assert pickers[where]["filters"][1].startswith("DEM GeoTIFF"), pickers[where]


def test_an_output_that_cannot_be_written_is_refused_before_any_work(desktop):
    """Item 2: the difference into a folder that cannot be made: the dialog's log names it, the
    engine never ran, and QGIS adds no "layers were not correctly generated"."""
    blocked = desktop["summary"]["runs"]["blocked"]
    assert not blocked["ok"], blocked
    assert "cannot write into the folder" in blocked["log"] and "is a file, not a folder" in blocked["log"], blocked
    assert "Registering" not in blocked["log"] and "Reading" not in blocked["log"], blocked["log"]
    assert "not correctly generated" not in blocked["log"]


def test_a_clean_log_one_line_per_error_and_the_report_in_the_results_viewer(desktop):
    """Item 7 (and 12's MDAL line): a run adds nothing to the Log Messages panel about the LAS
    inputs and prints no "Unable to load mesh"; the same file twice is said once in the dialog's
    log; the HTML report is listed in the Results Viewer, which is open."""
    runs = desktop["summary"]["runs"]
    good, same = runs["good"], runs["same"]
    assert good["ok"], good["log"][-2000:]
    noise = [m for run in runs.values() for m in run["messages"] if "Cannot open" in m or "mesh" in m.lower()]
    assert noise == [], noise
    assert good["messages"] == [], good["messages"]  # a good run adds nothing to the Log Messages panel
    assert sum("is the same file" in m for m in same["messages"]) == 1, same["messages"]
    assert "Unable to load mesh" not in desktop["stderr"]
    assert not same["ok"] and same["log"].count("is the same file") == 1, same["log"]
    viewer = good["results_viewer"]
    report = str(desktop["out"] / "r.html")
    assert report in viewer["listed"] and viewer["open"], viewer
    assert any(item.startswith("Estimate soil volume change: r.html") for item in viewer["items"]), viewer


def test_model_builder_offers_file_inputs_and_the_model_runs_from_its_dialog(desktop):
    """Item 10: Model Builder's child dialog offers File (and String) inputs for Before and After
    (was: only Point Cloud or Map Layer inputs, which fail without PDAL); the model built of File
    inputs runs from its dialog and returns the volumes table."""
    model = desktop["summary"]["modeler"]
    for key in ("BEFORE", "AFTER"):
        assert "input of type file" in model["offered"][key], model["offered"]
    assert model["run"]["ok"], model["log_tail"]
    volumes = model["run"]["results"].get("volumes", "")
    assert volumes and Path(volumes.split("|")[0]).is_file(), model["run"]
