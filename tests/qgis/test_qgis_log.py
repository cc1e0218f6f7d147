"""QGIS's log of a run: no OGR or MDAL noise about the LAS/LAZ inputs, an engine error said once,
and the HTML report listed in the Results Viewer (issue 49, items 7 and 12)."""

from __future__ import annotations

from pathlib import Path

import pytest
from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingException, QgsProject

from .recording import RecordingFeedback


@pytest.fixture
def messages():
    """What reaches QGIS's message log (the desktop's Log Messages panel) meanwhile."""
    seen: list[str] = []

    def keep(message, tag, _level) -> None:
        seen.append(f"{tag}: {message}")

    QgsApplication.messageLog().messageReceived.connect(keep)
    yield seen
    QgsApplication.messageLog().messageReceived.disconnect(keep)


def described(alg, values: dict) -> list[str]:
    """Every way QGIS writes a run's parameters (the dialog's log and history, the Python and
    qgis_process commands, each input's value as text and JSON)."""
    context = QgsProcessingContext()
    context.setProject(QgsProject.instance())
    out = [alg.asPythonCommand(values, context), alg.asQgisProcessCommand(values, context)[0]]
    out.append(str(alg.asMap(values, context)))
    for name, value in values.items():
        param = alg.parameterDefinition(name)
        out += [str(param.valueAsString(value, context)), str(param.valueAsJsonObject(value, context))]
        out.append(param.valueAsPythonString(value, context))
    QgsApplication.processEvents()
    return out


def test_las_inputs_are_not_tried_as_vector_or_mesh_layers(provider, scene_dir, tmp_path, messages, capfd):
    """The parameters of a run written out (the algorithm dialog, Batch and qgis_process do it for
    every run): the file paths as they are, no "Cannot open ....las" from OGR in the log and no
    "Unable to load mesh (null)" from MDAL on the terminal (was: both, for each LAS/LAZ input, two to
    three times per run)."""
    before, after = str(scene_dir / "before.las"), str(scene_dir / "after.las")
    registry = QgsApplication.processingRegistry()
    runs = {
        "estimatevolumechange": {"BEFORE": before, "AFTER": after},
        "registerpointclouds": {"BEFORE": before, "AFTER": after},
        "pointcloudtodem": {"INPUT": before},
        "volumeseries": {"EPOCHS": [before, after, before]},
    }
    for name, values in runs.items():
        texts = described(registry.algorithmById(f"soilvolume:{name}"), values)
        assert all(before in text for text in texts[:3]), texts
    assert not [m for m in messages if ".las" in m], messages
    assert "Unable to load mesh" not in capfd.readouterr().err


def test_an_engine_error_is_said_once(run_alg, scene_dir, tmp_path):
    """One survey as both: the engine's error reaches QGIS once, as the run's error (was: also as
    a grey debug line "soilvolume: error: ..." before the red one)."""
    feedback = RecordingFeedback()
    same = str(scene_dir / "after.las")
    with pytest.raises(QgsProcessingException, match="is the same file") as info:
        run_alg(
            "estimatevolumechange",
            {"BEFORE": same, "AFTER": same, "DIFFERENCE": str(tmp_path / "d.tif")},
            feedback=feedback,
        )
    said = feedback.debug + feedback.infos + feedback.warnings + feedback.errors
    assert not [line for line in said if "same file" in line], said
    assert str(info.value).count("is the same file") == 1, str(info.value)


def test_the_html_report_is_listed_in_the_results_viewer(estimate_run):
    """The report is in Processing's Results Viewer (as QGIS's own HTML outputs are; the viewer
    opens on it, a double click opens the page): was neither opened nor listed."""
    from processing.core.ProcessingResults import resultsList

    listed = [r for r in resultsList.getResults() if r.filename == estimate_run["REPORT"]]
    assert len(listed) == 1 and Path(listed[0].filename).is_file(), [r.filename for r in resultsList.getResults()]
    assert listed[0].name == "Estimate soil volume change: report.html" and listed[0].timestamp is not None
