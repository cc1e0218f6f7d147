"""The desktop GUI under a virtual X server (Xvfb): the algorithm dialog, the styled outputs
loaded by Processing, their stacking order and legends; screenshots kept in tests/artefacts/."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

XVFB_RUN = shutil.which("xvfb-run")
pytestmark = pytest.mark.skipif(XVFB_RUN is None, reason="xvfb-run is not installed (apt-get install xvfb)")
HERE = Path(__file__).resolve().parent
ARTEFACTS = HERE.parent / "artefacts"


@pytest.fixture(scope="module")
def session(plugins_dir, scene_dir, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("gui")
    env = {k: v for k, v in os.environ.items() if k not in ("QT_QPA_PLATFORM", "PYTHONPATH", "QGIS_OPTIONS_PATH")}
    env["QGIS_CUSTOM_CONFIG_PATH"] = str(out / "profile")
    command = [
        XVFB_RUN,
        "-a",
        "-s",
        "-screen 0 1400x1000x24",
        sys.executable,
        str(HERE / "gui_session.py"),
        str(plugins_dir),
        str(scene_dir / "before.las"),
        str(scene_dir / "after.las"),
        str(out),
        str(ARTEFACTS),
    ]
    run = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300, cwd=str(out))
    assert run.returncode == 0, run.stderr[-3000:] + run.stdout[-2000:]
    line = [text for text in run.stdout.splitlines() if text.startswith("{")][-1]
    return json.loads(line)


def test_dialog_widgets(session):
    dialog = session["dialog"]
    assert any("meters" in text.lower() for text in dialog["radius_labels"]), dialog  # a distance
    assert dialog["radius_text"] == "30.0", dialog  # not 30.000000
    assert dialog["fine_value"] == "icp"
    assert dialog["before_value"].endswith("before.las")
    assert not dialog["registered_created"]  # the registered cloud is off by default
    listed = {
        side: [e for e in dialog[f"{side}_dropdown"] if e.startswith("design DEM")] for side in ("before", "after")
    }
    assert listed["before"], dialog  # a raster layer of the project as the reference (a design surface)
    assert not listed["after"], dialog  # the after survey is a point cloud
    assert (ARTEFACTS / "estimate_dialog.png").stat().st_size > 10_000


def test_layer_dropdowns_start_empty(session):
    """A raster in the project (a difference, a DEM) is not preselected as the estimate's Before
    surface nor as Volume from DEMs' Before and After (was: the project's first raster layer);
    the dialogs refuse to run until one is picked, and a layer given is kept."""
    defaults = session["defaults"]
    estimate, dems = defaults["soilvolume:estimatevolumechange"], defaults["soilvolume:volumefromdems"]
    assert estimate["BEFORE"] is None and estimate["run"] == "refused: BEFORE", estimate
    assert dems["BEFORE"] is None and dems["AFTER"] is None and dems["run"] == "refused: BEFORE", dems
    assert defaults["picked"] == {"BEFORE": True, "AFTER": True}, defaults


def test_series_dialog_keeps_preset_files_in_order(session, scene_dir):
    """The series dialog opened with files (as execAlgorithmDialog passes them) keeps them all, in
    order, repeats included, and runs with them (was: LAS paths dropped where QGIS cannot load
    them as layers)."""
    files = [str(scene_dir / name) for name in ("after.las", "before.las", "after.las")]
    series = session["defaults"]["series"]
    assert series["widget"] == files and series["run"] == files, series


def test_outputs_loaded_styled_and_stacked(session, truth):
    assert session["net"] == pytest.approx(truth["net"], rel=0.03)
    order = session["order"]
    assert order[0] == "Areas of significant change (after)" and len(order) == 5, order  # on top, outlined
    assert order[1] == "Difference (after)", order  # named after the pair
    assert order.index("Vertical correction (after)") < order.index("DEM before (before)")
    areas = session["change_areas"]
    assert areas["layers"] == ["Areas of significant change (after)"], areas
    assert areas["categories"] == ["cut", "fill"]  # styled: cut red, fill blue
    assert all(fill <= 64 and outline == 255 for fill, outline in areas["alphas"]), areas  # light fill
    for kind in ("cut", "fill"):  # the polygons hold the headline's volumes
        assert areas["sums"].get(kind, 0.0) == pytest.approx(areas["headline"][kind], rel=1e-3, abs=0.5), areas
    assert (ARTEFACTS / "layers_and_map.png").stat().st_size > 20_000


def test_legends_show_the_styled_range(session):
    for row in session["legends"]:
        assert row["legend"] == pytest.approx(row["style"]), row["name"]
        assert row["nodata"] == -9999, row["name"]
        if row["name"].startswith("DEM"):
            assert 55 < row["legend"][0] < row["legend"][1] < 75  # the scene's heights, not 0-100
        else:
            assert row["legend"][0] == pytest.approx(-row["legend"][1])


def test_batch_of_three_rows_has_no_red_errors(plugins_dir, scene_dir, tmp_path):
    """QGIS's Batch dialog, three rows of one pair with the HTML report asked for and the DEM
    columns left blank, results loaded: no "The following layers were not correctly generated"
    (blank layer outputs were registered as a layer "" to load) and no Python error (QGIS's Batch
    dialog raises a TypeError for every HTML output it hands to its Results Viewer); three
    groups, one per run, the polygons on top in each."""
    env = {k: v for k, v in os.environ.items() if k not in ("QT_QPA_PLATFORM", "PYTHONPATH", "QGIS_OPTIONS_PATH")}
    env["QGIS_CUSTOM_CONFIG_PATH"] = str(tmp_path / "profile")
    pair = f"{scene_dir / 'before.las'},{scene_dir / 'after.las'}"
    command = [XVFB_RUN, "-a", "-s", "-screen 0 1400x1000x24", sys.executable, str(HERE / "batch_session.py")]
    run = subprocess.run(
        [*command, str(plugins_dir), str(tmp_path), pair, pair, pair],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=str(tmp_path),
    )
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout.split("RESULT", 1)[1])
    assert summary["python_errors"] == [], summary["python_errors"]
    assert "not correctly generated" not in summary["log"], summary["log"][-2000:]
    assert summary["reports"] == [True] * 3 and None not in summary["nets"], summary
    runs = {name: layers for name, layers in summary["groups"].items() if name.startswith("Soil volume: before")}
    assert len(runs) == 3, summary["groups"]
    for layers in runs.values():
        assert [name.split(" (")[0] for name in layers] == ["Areas of significant change", "Difference"], runs
