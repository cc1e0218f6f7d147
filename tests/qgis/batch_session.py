"""QGIS's real Batch dialog (processing's BatchAlgorithmDialog) on two pairs in a desktop session
under Xvfb, run the way the dialog's Run button runs it (pooled processing threads), outputs
loaded into the project; prints a JSON summary (each row's net, QGIS alive afterwards).

Usage (a stock QGIS Python, nothing of the dev venv): batch_session.py PLUGINS_DIR OUT_DIR PAIR...
where each PAIR is BEFORE,AFTER.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from qgis.core import QgsApplication, QgsProject


def main(plugins_dir: str, out_dir: str, *pairs: str) -> int:
    app = QgsApplication([], True)
    app.initQgis()
    sys.path.insert(0, str(Path(QgsApplication.pkgDataPath()) / "python" / "plugins"))
    sys.path.append(plugins_dir)
    from processing.core.Processing import Processing
    from processing.gui.BatchAlgorithmDialog import BatchAlgorithmDialog

    Processing.initialize()
    from soilvolume_qgis.processing.provider import SoilVolumeProvider

    provider = SoilVolumeProvider()
    QgsApplication.processingRegistry().addProvider(provider)
    alg = QgsApplication.processingRegistry().createAlgorithmById("soilvolume:estimatevolumechange")
    dialog = BatchAlgorithmDialog(alg)
    out = Path(out_dir)
    rows = []
    for i, pair in enumerate(pairs):
        before, after = pair.split(",")
        outputs = {
            key: str(out / f"row{i}_{key.lower()}{ext}")
            for key, ext in (("DIFFERENCE", ".tif"), ("REPORT_JSON", ".json"))
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
    layers = sorted(layer.name() for layer in QgsProject.instance().mapLayers().values())
    summary = {"nets": nets, "seconds": time.time() - t0, "layers": layers, "alive": True, "pid": os.getpid()}
    dialog.close()
    print("RESULT" + json.dumps(summary), flush=True)
    QgsProject.instance().removeAllMapLayers()
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
