"""An HTML report listed in Processing's Results Viewer, as QGIS lists its own HTML outputs.

The reports are file outputs, not HTML outputs (see :class:`.params.ReportDestination`: QGIS 3.40's
Batch dialog fails on HTML outputs), so QGIS itself lists none of them; here each run's report is
listed (the Results Viewer opens on it; a double click opens the page in the browser), from the
algorithm dialog, Batch and models alike.
"""

from __future__ import annotations

import time
from pathlib import Path

from qgis.core import QgsProcessingAlgorithm


def list_report(alg: QgsProcessingAlgorithm, path: str | None) -> bool:
    """List the report at ``path`` in the Results Viewer; whether it was (not without QGIS's
    Processing plugin, nor for a file that is not there)."""
    if not path or not Path(path).is_file():
        return False
    try:
        from processing.core.ProcessingResults import resultsList  # QGIS's Processing plugin
    except ImportError:
        return False
    name = f"{alg.displayName()}: {Path(path).name}"
    resultsList.addResult(icon=alg.icon(), name=name, timestamp=time.localtime(), result=str(path))
    return True
