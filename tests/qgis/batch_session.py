"""QGIS's real Batch dialog (processing's BatchAlgorithmDialog) on two pairs in a desktop session
under Xvfb, run the way the dialog's Run button runs it (pooled processing threads), outputs
loaded into the project; prints a JSON summary (each row's net, the Layers panel's groups, the
dialog's log, Python errors raised meanwhile, and QGIS's own Processing run in the same process
afterwards).

Usage (a stock QGIS Python, nothing of the dev venv): batch_session.py PLUGINS_DIR OUT_DIR PAIR...
where each PAIR is BEFORE,AFTER.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

from qgis.core import QgsApplication, QgsProject
from session import start  # tests/qgis/session.py, beside this script


def groups() -> dict[str, list[str]]:
    """The Layers panel: each group's layers, top first (and the root's own layers under "")."""
    root = QgsProject.instance().layerTreeRoot()
    tree = {"": [node.name() for node in root.children() if node.nodeType() == node.NodeLayer]}
    for group in root.findGroups():
        tree[group.name()] = [layer.name() for layer in group.findLayers()]
    return tree


def still_working(out: Path) -> dict:
    """After the batch, in the same process: QGIS's own Processing still runs (statistics of the
    first row's difference raster)."""
    from qgis import processing

    stats = processing.run("native:rasterlayerstatistics", {"INPUT": str(out / "row0_difference.tif"), "BAND": 1})
    return {"mean": stats["MEAN"], "min": stats["MIN"], "max": stats["MAX"]}


ERRORS: list[str] = []  # Python exceptions raised in Qt's callbacks (QGIS shows them in a dialog)


def main(plugins_dir: str, out_dir: str, *pairs: str) -> int:
    app, _provider, _modules = start(plugins_dir, gui=True)
    sys.excepthook = lambda kind, value, tb: ERRORS.append("".join(traceback.format_exception(kind, value, tb)))
    from processing.gui.BatchAlgorithmDialog import BatchAlgorithmDialog
    from qgis.PyQt.QtWidgets import QTextEdit

    alg = QgsApplication.processingRegistry().createAlgorithmById("soilvolume:estimatevolumechange")
    dialog = BatchAlgorithmDialog(alg)
    out = Path(out_dir)
    rows = []
    for i, pair in enumerate(pairs):
        before, after = pair.split(",")
        outputs = {
            key: str(out / f"row{i}_{key.lower()}{ext}")
            for key, ext in (
                ("DIFFERENCE", ".tif"),
                ("CHANGE_AREAS", ".gpkg"),
                ("REPORT", ".html"),
                ("REPORT_JSON", ".json"),
            )
        }
        rows.append({"PARAMETERS": {"BEFORE": before, "AFTER": after}, "OUTPUTS": outputs})
    panel = dialog.mainWidget()
    panel.load_batch_file_3_40_version({"rows": rows})
    panel.checkLoadLayersOnCompletion.setChecked(True)  # as an analyst does: the results loaded
    dialog.show()
    t0 = time.time()
    dialog.runAlgorithm()
    while time.time() - t0 < 600:
        QgsApplication.processEvents()
        time.sleep(0.05)
        if (
            all((out / f"row{i}_report_json.json").is_file() for i in range(len(rows)))
            and not QgsApplication.taskManager().countActiveTasks()
        ):
            break
    for _ in range(40):
        QgsApplication.processEvents()
        time.sleep(0.05)
    nets = []
    for i in range(len(rows)):
        path = out / f"row{i}_report_json.json"
        nets.append(json.loads(path.read_text())["volume_m3"]["net"] if path.is_file() else None)
    seconds = time.time() - t0
    log = next((w.toPlainText() for w in dialog.findChildren(QTextEdit) if w.objectName() == "txtLog"), "")
    dialog.close()
    summary = {"nets": nets, "seconds": seconds, "groups": groups(), "after": still_working(out)}
    summary.update(
        log=log, python_errors=ERRORS, reports=[(out / f"row{i}_report.html").is_file() for i in range(len(rows))]
    )
    print("RESULT" + json.dumps(summary), flush=True)
    QgsProject.instance().removeAllMapLayers()
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
