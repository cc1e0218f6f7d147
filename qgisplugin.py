"""The plugin object QGIS creates through ``classFactory``: the Processing provider registered,
a menu entry and a toolbar button, the engine's environment checked. Above both ``processing/``
(the provider) and ``plugin/`` (the engine's environment and the child process it runs in)."""

from __future__ import annotations

from typing import Any

from qgis.core import QgsApplication
from qgis.PyQt.QtGui import QIcon
from qgis.PyQt.QtWidgets import QAction

from .plugin.installer import DependencyBar
from .processing.base import ICON
from .processing.provider import SoilVolumeProvider

MENU = "&Soil volume change"
MAIN_ALGORITHM = "soilvolume:estimatevolumechange"


class SoilVolumePlugin:
    """Registers the Processing provider; adds a menu entry and a toolbar button that open the
    main algorithm's dialog; checks the engine's environment once and offers to install it."""

    def __init__(self, iface: Any) -> None:
        self.iface = iface
        self.provider: SoilVolumeProvider | None = None
        self.action: QAction | None = None
        self.install_action: QAction | None = None
        self.dependencies = DependencyBar(iface)

    def initProcessing(self) -> None:  # noqa: N802 - QGIS API
        registry = QgsApplication.processingRegistry()
        if self.provider is None and registry.providerById("soilvolume") is None:
            self.provider = SoilVolumeProvider()
            registry.addProvider(self.provider)

    def initGui(self) -> None:  # noqa: N802 - QGIS API
        self.initProcessing()
        self.action = QAction(QIcon(str(ICON)), "Estimate soil volume change…", self.iface.mainWindow())
        self.action.setObjectName("soilvolumeEstimate")
        self.action.setToolTip("Estimate soil volume change between two point cloud surveys")
        self.action.triggered.connect(self.open_dialog)
        self.iface.addPluginToMenu(MENU, self.action)
        self.iface.addToolBarIcon(self.action)
        self.install_action = QAction("Install dependencies…", self.iface.mainWindow())
        self.install_action.triggered.connect(self.install_dependencies)
        self.iface.addPluginToMenu(MENU, self.install_action)
        self.dependencies.check()

    def install_dependencies(self) -> None:
        """Install or update the engine's environment (menu entry; the bar's button does the
        same, and so does ``qgis_process run soilvolume:installdependencies``): quick when it is
        up to date."""
        self.dependencies.install()

    def open_dialog(self) -> None:
        """Open the Processing dialog of the main algorithm."""
        from qgis import processing  # QGIS's Processing framework, never this plugin's folder

        processing.execAlgorithmDialog(MAIN_ALGORITHM, {})

    def unload(self) -> None:
        self.dependencies.close()
        if self.install_action is not None:
            self.iface.removePluginMenu(MENU, self.install_action)
            self.install_action.deleteLater()
            self.install_action = None
        if self.action is not None:
            self.iface.removePluginMenu(MENU, self.action)
            self.iface.removeToolBarIcon(self.action)
            self.action.deleteLater()
            self.action = None
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
