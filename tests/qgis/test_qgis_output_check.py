"""Every output checked writable before any work (issue 49 item 2, issue 51 item 5): one
QgsProcessingException naming the output and why, the engine never started, nothing written."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from qgis.core import QgsProcessingException, QgsProject, QgsRasterLayer

from .recording import RecordingFeedback


def refused(run_alg, name: str, values: dict) -> tuple[str, RecordingFeedback, float]:
    """The run's error, its feedback, and how long it took to say it."""
    feedback = RecordingFeedback()
    t0 = time.perf_counter()
    with pytest.raises(QgsProcessingException) as info:
        run_alg(name, values, feedback=feedback)
    return str(info.value), feedback, time.perf_counter() - t0


def engine_ran(feedback: RecordingFeedback) -> bool:
    """Whether the engine started (its progress or log reached the feedback)."""
    return bool(feedback.progress) or any(line.startswith(("Reading", "Gridding")) for line in feedback.infos)


def unwritable_folder(tmp_path: Path) -> Path:
    """A folder this process cannot write into: a read-only one (root writes into any folder of a
    writable file system, so there the kernel's read-only /proc/sys)."""
    if os.geteuid() != 0:
        folder = tmp_path / "locked"
        folder.mkdir()
        folder.chmod(0o555)
        return folder
    if os.access("/proc/sys", os.W_OK):
        pytest.skip("no folder this process cannot write into")
    return Path("/proc/sys")


def test_a_folder_without_write_permission_is_refused_before_the_engine_runs(run_alg, scene_dir, tmp_path):
    """The estimate's difference into a folder it cannot write into: refused at once, naming the
    output and the folder (was: registration, gridding and volumes ran, then the copy failed)."""
    folder = unwritable_folder(tmp_path)
    before, after = str(scene_dir / "before.las"), str(scene_dir / "after.las")
    values = {"BEFORE": before, "AFTER": after, "DIFFERENCE": str(folder / "d.tif"), "REPORT": str(tmp_path / "r.html")}
    message, feedback, _seconds = refused(run_alg, "estimatevolumechange", values)
    assert message.startswith("Difference (after − before, corrected): cannot write into the folder"), message
    assert str(folder) in message and "permission denied" in message, message
    assert not engine_ran(feedback), feedback.infos
    assert not (tmp_path / "r.html").exists()  # nothing of the run written elsewhere either


@pytest.mark.parametrize("where", ["file in the way", "a folder at the file's path"])
def test_every_algorithm_checks_its_outputs_first(run_alg, scene_dir, tmp_path, where):
    blocker = tmp_path / "taken"
    blocker.write_text("a file, not a folder")
    target = blocker / "sub" if where == "file in the way" else tmp_path / "folder.tif"
    if where != "file in the way":
        target.mkdir()
    cloud = str(scene_dir / "after.las")
    runs = {
        "pointcloudtodem": {
            "INPUT": cloud,
            "OUTPUT": str(target / "dem.tif") if where == "file in the way" else str(target),
        },
        "registerpointclouds": {
            "BEFORE": str(scene_dir / "before.las"),
            "AFTER": cloud,
            "OUTPUT": str(target / "r.laz"),
        },
        "volumeseries": {"EPOCHS": [str(scene_dir / "before.las"), cloud], "OUTPUT_FOLDER": str(blocker / "site")},
    }
    for name, values in runs.items():
        if where != "file in the way" and name != "pointcloudtodem":
            continue
        message, feedback, seconds = refused(run_alg, name, values)
        assert not engine_ran(feedback) and seconds < 5, (name, feedback.infos)
        expected = f"{blocker} is a file, not a folder" if where == "file in the way" else f"{target} is a folder"
        assert expected in message and "nothing was computed" in message, message
    assert blocker.read_text() == "a file, not a folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["taken"] + (["folder.tif"] if target.is_dir() else []))


@pytest.fixture
def windows(monkeypatch, plugin_package):
    """This system taken for Windows, where a file open in QGIS cannot be replaced."""
    from soilvolume_qgis.processing import outputcheck

    monkeypatch.setattr(outputcheck, "LOCKS_OPEN_FILES", True)


def test_a_geotiff_loaded_in_qgis_is_named_before_the_run_on_windows(run_alg, scene_dir, tmp_path, windows):
    """On Windows, writing over a GeoTIFF QGIS has loaded failed with "Access is denied" after the
    whole run (os.replace): now refused first, saying to remove the layer; once removed it runs."""
    out = tmp_path / "dem.tif"
    values = {"INPUT": str(scene_dir / "after.las"), "CELL": 2.0, "OUTPUT": str(out)}
    run_alg("pointcloudtodem", values)
    layer = QgsRasterLayer(str(out), "my dem")
    assert layer.isValid()
    QgsProject.instance().addMapLayer(layer)
    before = out.read_bytes()
    try:
        message, feedback, _seconds = refused(run_alg, "pointcloudtodem", values)
    finally:
        QgsProject.instance().removeMapLayer(layer.id())
    assert f"cannot replace {out}: it is open in QGIS as the layer 'my dem'; remove that layer" in message, message
    assert not engine_ran(feedback) and out.read_bytes() == before
    assert Path(run_alg("pointcloudtodem", values)["OUTPUT"]) == out  # the layer removed: it runs


def test_elsewhere_a_loaded_geotiff_is_replaced(run_alg, scene_dir, tmp_path):
    """On Linux and macOS a loaded file can be replaced: no refusal there."""
    out = tmp_path / "dem.tif"
    values = {"INPUT": str(scene_dir / "after.las"), "CELL": 2.0, "OUTPUT": str(out)}
    run_alg("pointcloudtodem", values)
    layer = QgsRasterLayer(str(out), "my dem")
    QgsProject.instance().addMapLayer(layer)
    try:
        assert run_alg("pointcloudtodem", values)["OUTPUT"] == str(out)
    finally:
        QgsProject.instance().removeMapLayer(layer.id())


def test_a_file_name_of_dot_dot_is_refused_first(run_alg, scene_dir, tmp_path):
    """OUTPUT=<folder>/.. names a folder: refused before the engine (was: the engine ran, then
    GDAL's RuntimeError came through as a traceback, twice)."""
    message, feedback, _seconds = refused(
        run_alg, "pointcloudtodem", {"INPUT": str(scene_dir / "after.las"), "OUTPUT": str(tmp_path / "x" / "..")}
    )
    assert "is a folder; give a file name" in message and not engine_ran(feedback), message
    assert list(tmp_path.iterdir()) == []


def test_destinations_as_the_dialog_gives_them_are_checked(run_alg, scene_dir, tmp_path):
    """The algorithm dialog gives a layer output as an output definition (its path a QgsProperty,
    whose text QGIS's Python returns with a flag): checked too (was: skipped, so the desktop dialog
    ran the engine and then failed)."""
    from qgis.core import QgsProcessingOutputLayerDefinition

    blocker = tmp_path / "taken"
    blocker.write_text("a file, not a folder")
    out = QgsProcessingOutputLayerDefinition(str(blocker / "sub" / "dem.tif"))
    message, feedback, _seconds = refused(
        run_alg, "pointcloudtodem", {"INPUT": str(scene_dir / "after.las"), "OUTPUT": out}
    )
    assert f"{blocker} is a file, not a folder" in message and not engine_ran(feedback), message


def test_a_series_folder_with_a_loaded_file_is_named_on_windows(run_alg, scene_dir, tmp_path, windows):
    """The series replaces the files of its output folder: on Windows one of them loaded in QGIS
    is named before the run, with the layer to remove."""
    folder = tmp_path / "site"
    folder.mkdir()
    dem = folder / "dem_epoch0.tif"
    run_alg("pointcloudtodem", {"INPUT": str(scene_dir / "after.las"), "CELL": 2.0, "OUTPUT": str(dem)})
    layer, before = QgsRasterLayer(str(dem), "epoch 0"), dem.read_bytes()
    QgsProject.instance().addMapLayer(layer)
    try:
        epochs = [str(scene_dir / "before.las"), str(scene_dir / "after.las")]
        message, feedback, _s = refused(run_alg, "volumeseries", {"EPOCHS": epochs, "OUTPUT_FOLDER": str(folder)})
    finally:
        QgsProject.instance().removeMapLayer(layer.id())
    assert "dem_epoch0.tif is open in QGIS as the layer 'epoch 0'; remove that layer" in message, message
    assert not engine_ran(feedback) and dem.read_bytes() == before
    assert not [p for p in folder.iterdir() if not p.name.startswith("dem_epoch0.tif")]  # (QGIS's .aux.xml)
