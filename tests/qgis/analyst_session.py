"""Run inside the QGIS desktop itself (``qgis --code analyst_session.py``) under Xvfb, the plugin
enabled in a clean profile and the engine's environment given (``SOILVOLUME_ENGINE_ENV``): what a
new analyst clicks (issue 49, items 1, 2, 7 and 10). Writes ``$SOILVOLUME_ANALYST_OUT/summary.json``
and quits QGIS.

- the *Before* "…" file pickers of the algorithm dialog and of Batch: the filter they open on;
- runs in the algorithm dialog: a good pair (the Log Messages panel, the Results Viewer), the same
  file twice (the error in the dialog's log), a difference into a folder that cannot be made;
- Model Builder: which model inputs its child dialog offers for *Before*/*After*, and a model of
  File inputs run from its own dialog.

Environment: SOILVOLUME_ANALYST_OUT (folder), SOILVOLUME_ANALYST_SCENE (folder with before.las,
after.las).
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path

from qgis.core import Qgis, QgsApplication, QgsProcessingContext, QgsSettings
from qgis.PyQt import sip
from qgis.PyQt.QtCore import QTimer
from qgis.PyQt.QtWidgets import QApplication, QComboBox, QFileDialog, QTextEdit, QToolButton
from qgis.utils import iface

OUT = Path(os.environ["SOILVOLUME_ANALYST_OUT"])
SCENE = Path(os.environ["SOILVOLUME_ANALYST_SCENE"])
ESTIMATE = "soilvolume:estimatevolumechange"
ERRORS: list[str] = []  # Python exceptions QGIS would show in its error dialog
MESSAGES: list[str] = []  # the Log Messages panel
KEPT: list = []  # the dialogs run


def note(text: str) -> None:
    with (OUT / "progress.log").open("a", encoding="utf-8") as log:
        log.write(f"{time.strftime('%H:%M:%S')} {text}\n")


def wait(seconds: float, until=lambda: False) -> bool:
    end = time.time() + seconds
    while time.time() < end:
        QgsApplication.processEvents()
        if until():
            return True
        time.sleep(0.05)
    return until()


def file_dialog_of(button: QToolButton) -> dict:
    """Click a "…" button; read the file dialog it opens (its filters, the one it opens on, the
    scene's files that filter shows), then close it."""
    seen: dict = {}

    def read() -> None:
        dialog = QApplication.activeModalWidget()
        if isinstance(dialog, QFileDialog):
            dialog.setDirectory(str(SCENE))
            chosen = dialog.selectedNameFilter()
            patterns = chosen[chosen.find("(") + 1 : chosen.rfind(")")].split()
            seen.update(filters=dialog.nameFilters(), opens_on=chosen, listed=_matching(patterns))
            dialog.reject()
        elif not seen.get("tries", 0) > 40:
            seen["tries"] = seen.get("tries", 0) + 1
            QTimer.singleShot(100, read)

    QTimer.singleShot(300, read)
    button.click()  # modal: returns once read() closed it
    wait(0.5)
    return seen


def _matching(patterns: list[str]) -> list[str]:
    from fnmatch import fnmatch

    return sorted(p.name for p in SCENE.iterdir() if any(fnmatch(p.name, pattern) for pattern in patterns))


def dots(widget) -> QToolButton | None:
    buttons = [b for b in widget.findChildren(QToolButton) if b.text() in ("…", "...")]
    return buttons[0] if buttons else None


def pickers() -> dict:
    """The Before "…" of the algorithm dialog and of the Batch dialog's first row."""
    from processing.gui.AlgorithmDialog import AlgorithmDialog
    from processing.gui.BatchAlgorithmDialog import BatchAlgorithmDialog

    registry = QgsApplication.processingRegistry()
    QgsSettings().setValue("/Processing/LastInputPath", str(SCENE))
    out = {}
    dialog = AlgorithmDialog(registry.createAlgorithmById(ESTIMATE), parent=iface.mainWindow())
    dialog.show()
    wait(0.5)
    for key in ("BEFORE", "AFTER"):
        out[f"dialog_{key}"] = file_dialog_of(dots(dialog.mainWidget().wrappers[key].wrappedWidget()))
    dialog.close()
    batch = BatchAlgorithmDialog(registry.createAlgorithmById(ESTIMATE), iface.mainWindow())
    batch.show()
    wait(0.5)
    table = batch.mainWidget().tblParameters
    column = next(c for c in range(table.columnCount()) if table.horizontalHeaderItem(c).text().startswith("Before"))
    out["batch_BEFORE"] = file_dialog_of(dots(table.cellWidget(table.rowCount() - 1, column)))
    batch.close()
    return out


def run_in_dialog(algorithm, values: dict, seconds: float = 300) -> dict:
    """Run an algorithm (or a model) from its dialog as the Run button does; its log, the messages
    the Log Messages panel got meanwhile, whether it succeeded."""
    from processing.core.ProcessingConfig import ProcessingConfig
    from processing.gui.AlgorithmDialog import AlgorithmDialog

    ProcessingConfig.setSettingValue(ProcessingConfig.KEEP_DIALOG_OPEN, True)
    dialog = AlgorithmDialog(algorithm, parent=iface.mainWindow())
    dialog.setParameters(values)
    dialog.show()
    wait(0.3)
    done: list = []
    dialog.algorithmFinished.connect(lambda ok, results: done.append((ok, results)))
    first, seen = len(MESSAGES), [""]
    dialog.runAlgorithm()
    wait(seconds, lambda: bool(done) or "Execution failed" in log_of(dialog, seen))
    wait(1.0, lambda: log_of(dialog, seen) and False)
    ok, results = done[0] if done else (False, {})
    if not sip.isdeleted(dialog):
        dialog.hide()  # kept: closing deletes it, and with it what the next dialog shares
        KEPT.append(dialog)
    return {"ok": ok, "results": {k: str(v) for k, v in results.items()}, "log": seen[0], "messages": MESSAGES[first:]}


def log_of(dialog, seen: list) -> str:
    """The dialog's log (kept in ``seen``: the dialog may be gone when the run ends)."""
    if not sip.isdeleted(dialog):
        logs = [w for w in dialog.findChildren(QTextEdit) if w.objectName() == "txtLog"]
        seen[0] = logs[0].toPlainText() if logs else seen[0]
    return seen[0]


def runs() -> dict:
    """A good pair with the report, the same file twice, an output folder that cannot be made."""
    from processing.core.ProcessingResults import resultsList

    registry = QgsApplication.processingRegistry()
    before, after = str(SCENE / "before.las"), str(SCENE / "after.las")
    good = run_in_dialog(
        registry.createAlgorithmById(ESTIMATE),
        {
            "BEFORE": before,
            "AFTER": after,
            "CELL": 1.0,
            "DIFFERENCE": str(OUT / "d.tif"),
            "REPORT": str(OUT / "r.html"),
        },
    )
    dock = [w for w in QApplication.allWidgets() if type(w).__name__ == "ResultsDock"]
    good["results_viewer"] = {
        "listed": [r.filename for r in resultsList.getResults()],
        "open": bool(dock) and dock[0].isVisible(),
        "items": [dock[0].treeResults.topLevelItem(i).text(0) for i in range(dock[0].treeResults.topLevelItemCount())]
        if dock
        else [],
    }
    note("good run done")
    same = run_in_dialog(registry.createAlgorithmById(ESTIMATE), {"BEFORE": after, "AFTER": after})
    note("same-file run done")
    blocker = OUT / "taken"
    blocker.write_text("a file, not a folder")
    blocked = run_in_dialog(
        registry.createAlgorithmById(ESTIMATE),
        {"BEFORE": before, "AFTER": after, "DIFFERENCE": str(blocker / "sub" / "d.tif")},
    )
    return {"good": good, "same": same, "blocked": blocked}


def modeler() -> dict:
    """Model Builder's child dialog for the estimate in a model with one input of each type an
    analyst might add: which inputs it offers for Before and After; then a model of File inputs
    (what it offers) run from the model's own dialog."""
    from qgis.core import (
        QgsProcessingModelAlgorithm,
        QgsProcessingModelChildAlgorithm,
        QgsProcessingModelChildParameterSource,
        QgsProcessingModelOutput,
        QgsProcessingModelParameter,
    )
    from qgis.gui import QgsGui

    registry = QgsApplication.processingRegistry()
    model = QgsProcessingModelAlgorithm("Volumes of a pair", "Site")
    for kind in ("file", "pointcloud", "layer", "string"):
        param = registry.parameterType(kind).create(f"in_{kind}")
        param.setDescription(f"input of type {kind}")
        model.addModelParameter(param, QgsProcessingModelParameter(param.name()))
    child = QgsProcessingModelChildAlgorithm(ESTIMATE)
    child.setChildId("estimate")
    model.addChildAlgorithm(child)
    estimate = registry.algorithmById(ESTIMATE)
    offered = {}
    for key in ("BEFORE", "AFTER"):
        widget = QgsGui.processingGuiRegistry().createModelerParameterWidget(
            model, "estimate", estimate.parameterDefinition(key), QgsProcessingContext()
        )
        combos = [c for c in widget.findChildren(QComboBox)]
        offered[key] = sorted(
            {c.itemText(i) for c in combos for i in range(c.count()) if "input of type" in c.itemText(i)}
        )
    built = QgsProcessingModelAlgorithm("Volumes of a pair", "Site")
    for name, key in (("before", "BEFORE"), ("after", "AFTER")):
        param = registry.parameterType("file").create(name)
        built.addModelParameter(param, QgsProcessingModelParameter(name))
        child.addParameterSources(key, [QgsProcessingModelChildParameterSource.fromModelParameter(name)])
    output = QgsProcessingModelOutput("volumes", "Volumes")
    output.setChildId("estimate")
    output.setChildOutputName("VOLUMES")
    child.setModelOutputs({"volumes": output})
    built.addChildAlgorithm(child)
    built.toFile(str(OUT / "pair.model3"))
    loaded = QgsProcessingModelAlgorithm()
    loaded.fromFile(str(OUT / "pair.model3"))
    values = {"before": str(SCENE / "before.las"), "after": str(SCENE / "after.las")}
    ran = run_in_dialog(loaded.create(), {**values, "volumes": str(OUT / "volumes.gpkg")})
    return {"offered": offered, "run": {k: ran[k] for k in ("ok", "results")}, "log_tail": ran["log"][-1500:]}


def main() -> None:
    note("session started")
    summary: dict = {"qgis": Qgis.version()}
    try:
        summary["plugin_loaded"] = "soilvolume_qgis" in __import__("qgis.utils").utils.active_plugins
        summary["pickers"] = pickers()
        note("pickers read")
        summary["runs"] = runs()
        note("runs done")
        summary["modeler"] = modeler()
        note("modeler done")
    except Exception:  # noqa: BLE001 - reported in the summary
        summary["failure"] = traceback.format_exc()
    summary["python_errors"] = ERRORS
    (OUT / "summary.json").write_text(json.dumps(summary, indent=1))
    QTimer.singleShot(500, QgsApplication.instance().quit)


def _record(kind, value, tb) -> None:
    ERRORS.append("".join(traceback.format_exception(kind, value, tb))[-2000:])
    note("Python error: " + ERRORS[-1])


sys.excepthook = _record  # also replaces QGIS's error dialog, which would wait for a click
QgsApplication.messageLog().messageReceived.connect(lambda message, tag, _level: MESSAGES.append(f"{tag}: {message}"))
QTimer.singleShot(3000, main)
