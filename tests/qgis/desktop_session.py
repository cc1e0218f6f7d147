"""Run inside the QGIS desktop itself (``qgis --code desktop_session.py``) under Xvfb, with the
plugin installed from its zip into a clean profile, as a new analyst meets it: the message bar's
Install button clicked (when the bar is there), then QGIS's Batch dialog with one row per pair
run by its Run button's code with the results loaded. Writes a JSON summary to
``$SOILVOLUME_DESKTOP_OUT/summary.json`` and quits QGIS.

Environment: SOILVOLUME_DESKTOP_OUT (folder), SOILVOLUME_DESKTOP_PAIRS (``before,after;...``),
SOILVOLUME_DESKTOP_INSTALL_S (how long an install may take, default 1200).
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path

from qgis.core import Qgis, QgsApplication, QgsProject, QgsRenderContext, QgsVectorLayer
from qgis.PyQt.QtCore import QTimer
from qgis.utils import iface

OUT = Path(os.environ["SOILVOLUME_DESKTOP_OUT"])
ERRORS: list[str] = []  # Python exceptions QGIS would show in its error dialog


def note(text: str) -> None:
    """A progress line in ``progress.log`` (QGIS may stop at a modal dialog: see where)."""
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


def bar_messages() -> list[dict]:
    """What the message bar shows now: title, text and level of each item."""
    return [
        {"title": item.title(), "text": item.text(), "level": int(item.level())} for item in iface.messageBar().items()
    ]


def install() -> dict:
    """Click the bar's Install button (if shown) and wait for the success or the failure message."""
    from qgis.PyQt.QtWidgets import QPushButton

    seen: list[dict] = []
    wait(3.0)
    buttons = [
        b
        for item in iface.messageBar().items()
        for b in item.findChildren(QPushButton, "soilvolumeInstallDependencies")
    ]
    out = {"bar_at_start": bar_messages(), "clicked": bool(buttons)}
    if not buttons:
        return out
    t0 = time.time()
    note("clicking Install")
    buttons[0].click()

    def ended() -> bool:
        seen.extend(m for m in bar_messages() if m not in seen)
        ours = [m for m in seen if m["title"] == "Soil volume change"]
        return bool(ERRORS) or any(
            m["level"] in (int(Qgis.MessageLevel.Success), int(Qgis.MessageLevel.Critical)) for m in ours
        )

    wait(float(os.environ.get("SOILVOLUME_DESKTOP_INSTALL_S", "1200")), ended)
    wait(1.0)
    note(f"install ended: {seen}")
    out.update(seconds=time.time() - t0, messages=seen)
    return out


def log_of(dialog) -> tuple[str, str]:
    """(plain text, HTML) of the dialog's log panel."""
    from qgis.PyQt.QtWidgets import QTextEdit

    logs = [w for w in dialog.findChildren(QTextEdit) if w.objectName() == "txtLog"]
    return (logs[0].toPlainText(), logs[0].toHtml()) if logs else ("", "")


def batch(pairs: list[tuple[str, str]]) -> dict:
    """QGIS's Batch dialog, one row per pair, outputs as an analyst fills them in (the difference,
    the change areas and the HTML report), results loaded; run as its Run button does."""
    from processing.gui.BatchAlgorithmDialog import BatchAlgorithmDialog

    alg = QgsApplication.processingRegistry().createAlgorithmById("soilvolume:estimatevolumechange")
    dialog = BatchAlgorithmDialog(alg, iface.mainWindow())
    rows = []
    for i, (before, after) in enumerate(pairs):
        outputs = {
            key: str(OUT / f"row{i}_{key.lower()}{ext}")
            for key, ext in (("DIFFERENCE", ".tif"), ("CHANGE_AREAS", ".gpkg"), ("REPORT", ".html"))
        }
        rows.append({"PARAMETERS": {"BEFORE": before, "AFTER": after}, "OUTPUTS": outputs})
    panel = dialog.mainWidget()
    panel.load_batch_file_3_40_version({"rows": rows})
    panel.checkLoadLayersOnCompletion.setChecked(True)
    dialog.show()
    t0 = time.time()
    note("running the batch")
    dialog.runAlgorithm()
    wait(
        900,
        lambda: (
            all((OUT / f"row{i}_report.html").is_file() for i in range(len(rows)))
            and not QgsApplication.taskManager().countActiveTasks()
            and "Batch execution completed" in log_of(dialog)[0]
        ),
    )
    wait(2.0)
    text, page = log_of(dialog)
    note("batch ended")
    dialog.grab().save(str(OUT / "batch_dialog.png"))
    out = {
        "seconds": time.time() - t0,
        "reports": [(OUT / f"row{i}_report.html").is_file() for i in range(len(rows))],
        "not_generated": text.count("not correctly generated"),
        "red": page.count("color:#ff0000") + page.count("color:red"),
        "log_tail": text[-3000:],
    }
    dialog.close()
    return out


def layer_tree() -> dict:
    """Each group's layers, top first, with the polygons' symbols (fill and outline alpha)."""
    root = QgsProject.instance().layerTreeRoot()
    groups = {}
    for group in root.findGroups():
        groups[group.name()] = [node.layer().name() for node in group.findLayers()]
    symbols = []
    for layer in QgsProject.instance().mapLayers().values():
        if isinstance(layer, QgsVectorLayer) and layer.renderer() is not None:
            for symbol in layer.renderer().symbols(QgsRenderContext()):
                symbols.append({"fill_alpha": symbol.color().alpha(), "outline_alpha": _outline_alpha(symbol)})
    return {
        "groups": groups,
        "root_layers": [n.name() for n in root.children() if n.nodeType() == n.NodeLayer],
        "symbols": symbols,
    }


def _outline_alpha(symbol) -> int:
    layer = symbol.symbolLayer(0)
    return layer.strokeColor().alpha() if hasattr(layer, "strokeColor") else -1


def screenshot() -> None:
    """The window with the map zoomed to the first run's layers."""
    iface.mainWindow().resize(1600, 1000)
    canvas = iface.mapCanvas()
    first = QgsProject.instance().mapLayersByName("Difference (autzen_bmx_2023)")
    if first:
        iface.setActiveLayer(first[0])
        iface.zoomToActiveLayer()
    canvas.refresh()
    wait(2.0)
    canvas.waitWhileRendering()
    iface.mainWindow().grab().save(str(OUT / "qgis_window.png"))


def main() -> None:
    note("session started")
    summary: dict = {"python": sys.version.split()[0], "qgis": Qgis.version()}
    try:
        summary["plugin_loaded"] = "soilvolume_qgis" in __import__("qgis.utils").utils.active_plugins
        summary["install"] = install()
        pairs = [tuple(p.split(",")) for p in os.environ.get("SOILVOLUME_DESKTOP_PAIRS", "").split(";") if p]
        if pairs and summary["install"].get("clicked") is not None:
            summary["batch"] = batch(pairs)
            summary["tree"] = layer_tree()
            screenshot()
    except Exception:  # noqa: BLE001 - reported in the summary
        summary["failure"] = traceback.format_exc()
    summary["python_errors"] = ERRORS
    (OUT / "summary.json").write_text(json.dumps(summary, indent=1))
    QgsProject.instance().removeAllMapLayers()
    QTimer.singleShot(500, QgsApplication.instance().quit)


def _record(kind, value, tb) -> None:
    ERRORS.append("".join(traceback.format_exception(kind, value, tb))[-2000:])
    note("Python error: " + ERRORS[-1])


sys.excepthook = _record  # also replaces QGIS's error dialog, which would wait for a click
QTimer.singleShot(3000, main)
