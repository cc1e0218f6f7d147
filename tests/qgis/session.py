"""The start of the QGIS sessions the tests run as scripts (``gui_session.py``,
``batch_session.py``, ``thread_session.py``): a QgsApplication, QGIS's own Processing first on
the path, this plugin's provider registered."""

from __future__ import annotations

import sys
from pathlib import Path

from qgis.core import QgsApplication


def start(plugins_dir: str, gui: bool) -> tuple[QgsApplication, object, set[str]]:
    """(app, provider, the modules loaded before the plugin was imported)."""
    app = QgsApplication([], gui)
    app.initQgis()
    sys.path.insert(0, str(Path(QgsApplication.pkgDataPath()) / "python" / "plugins"))
    sys.path.append(plugins_dir)
    from processing.core.Processing import Processing

    Processing.initialize()
    modules = set(sys.modules)
    from soilvolume_qgis.processing.provider import SoilVolumeProvider

    provider = SoilVolumeProvider()
    QgsApplication.processingRegistry().addProvider(provider)
    return app, provider, modules
