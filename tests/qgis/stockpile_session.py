"""Run inside the QGIS desktop itself (``qgis --code stockpile_session.py``) under Xvfb, the plugin
enabled in a clean profile: the "Stockpile volumes" dialog as an analyst uses it (issue 54). The
toe polygons are loaded in the project, the dialog opened, the survey and the layer set in their
widgets, the name and density fields picked from the combos the layer fills, Run. Writes
``$SOILVOLUME_ANALYST_OUT/summary.json`` and quits QGIS.

Environment: SOILVOLUME_ANALYST_OUT (folder), SOILVOLUME_ANALYST_SCENE (folder with yard.las and
piles.gpkg).
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path

from processing.core.ProcessingConfig import ProcessingConfig
from processing.core.ProcessingResults import resultsList
from processing.gui.AlgorithmDialog import AlgorithmDialog
from qgis.core import Qgis, QgsApplication, QgsProject, QgsVectorLayer
from qgis.PyQt.QtCore import QTimer
from qgis.PyQt.QtWidgets import QApplication, QComboBox, QTextEdit
from qgis.utils import active_plugins, iface

OUT = Path(os.environ["SOILVOLUME_ANALYST_OUT"])
SCENE = Path(os.environ["SOILVOLUME_ANALYST_SCENE"])
STOCKPILE = "soilvolume:stockpilevolumes"
ERRORS: list[str] = []  # Python exceptions QGIS would show in its error dialog
KEPT: list = []  # the dialog, kept alive


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


def combo_items(widget) -> list[str]:
    """The entries of the field combo a field parameter's widget shows."""
    combos = [widget] if isinstance(widget, QComboBox) else widget.findChildren(QComboBox)
    return sorted({c.itemText(i) for c in combos for i in range(c.count()) if c.itemText(i)})


def fill(dialog, layer: QgsVectorLayer) -> dict:
    """Set the survey, the polygon layer and the fields in the dialog's widgets; what the field
    combos offered once the layer was chosen."""
    wrappers = dialog.mainWidget().wrappers
    wrappers["INPUT"].setParameterValue(str(SCENE / "yard.las"), dialog.processingContext())
    wrappers["PILES"].setParameterValue(layer, dialog.processingContext())
    wait(0.5)
    offered = {key: combo_items(wrappers[key].wrappedWidget()) for key in ("NAME_FIELD", "DENSITY_FIELD")}
    wrappers["NAME_FIELD"].setParameterValue("label", dialog.processingContext())
    wrappers["DENSITY_FIELD"].setParameterValue("rho", dialog.processingContext())
    wrappers["OUTPUT_FOLDER"].setParameterValue(str(OUT / "piles"), dialog.processingContext())
    return offered


def run_dialog() -> dict:
    """Load the polygons, open the dialog from the registry as the Toolbox does, fill it, Run."""
    layer = QgsVectorLayer(str(SCENE / "piles.gpkg"), "piles", "ogr")
    QgsProject.instance().addMapLayer(layer)
    ProcessingConfig.setSettingValue(ProcessingConfig.KEEP_DIALOG_OPEN, True)
    algorithm = QgsApplication.processingRegistry().createAlgorithmById(STOCKPILE)
    dialog = AlgorithmDialog(algorithm, parent=iface.mainWindow())
    dialog.show()
    wait(0.5)
    offered = fill(dialog, layer)
    done: list = []
    dialog.algorithmFinished.connect(lambda ok, results: done.append((ok, results)))
    dialog.runAlgorithm()
    wait(600, lambda: bool(done))
    wait(1.0)
    logs = [w for w in dialog.findChildren(QTextEdit) if w.objectName() == "txtLog"]
    ok, results = done[0] if done else (False, {})
    dialog.hide()
    KEPT.append(dialog)
    return {
        "layer_valid": layer.isValid(),
        "offered": offered,
        "ok": ok,
        "results": {k: str(v) for k, v in results.items()},
        "log": logs[0].toPlainText() if logs else "",
        "results_viewer": results_viewer(),
    }


def results_viewer() -> dict:
    """What the Results Viewer lists and whether it is open."""
    dock = [w for w in QApplication.allWidgets() if type(w).__name__ == "ResultsDock"]
    tree = dock[0].treeResults if dock else None
    return {
        "listed": [r.filename for r in resultsList.getResults()],
        "open": bool(dock) and dock[0].isVisible(),
        "items": [tree.topLevelItem(i).text(0) for i in range(tree.topLevelItemCount())] if tree else [],
    }


def main() -> None:
    note("session started")
    summary: dict = {"qgis": Qgis.version(), "plugin_loaded": "soilvolume_qgis" in active_plugins}
    try:
        summary["run"] = run_dialog()
        note("run done")
    except Exception:  # noqa: BLE001 - reported in the summary
        summary["failure"] = traceback.format_exc()
    summary["python_errors"] = ERRORS
    (OUT / "summary.json").write_text(json.dumps(summary, indent=1))
    QTimer.singleShot(500, QgsApplication.instance().quit)


def _record(kind, value, tb) -> None:
    ERRORS.append("".join(traceback.format_exception(kind, value, tb))[-2000:])
    note("Python error: " + ERRORS[-1])


sys.excepthook = _record  # also replaces QGIS's error dialog, which would wait for a click
QTimer.singleShot(3000, main)
