"""Common base of the plugin's algorithms."""

from __future__ import annotations

from pathlib import Path

from qgis.core import QgsProcessingAlgorithm
from qgis.PyQt.QtCore import QCoreApplication
from qgis.PyQt.QtGui import QIcon

ICON = Path(__file__).resolve().parent.parent / "resources" / "icon.svg"


class SoilVolumeAlgorithm(QgsProcessingAlgorithm):
    """Shared metadata from class attributes; subclasses set them and define the parameters and
    processAlgorithm."""

    _name = ""
    _display_name = ""
    _help = ""
    _tags = ""  # comma-separated
    _group = ""
    _group_id = ""

    def name(self) -> str:
        return self._name

    def displayName(self) -> str:  # noqa: N802 - Qt API
        return self.tr(self._display_name)

    def shortHelpString(self) -> str:  # noqa: N802
        return self.tr(self._help)

    def tags(self) -> list[str]:
        return self.tr(self._tags).split(",")

    def tr(self, text: str) -> str:
        return QCoreApplication.translate(type(self).__name__, text)

    def createInstance(self) -> SoilVolumeAlgorithm:  # noqa: N802 - Qt API
        return type(self)()

    def group(self) -> str:
        return self.tr(self._group)

    def groupId(self) -> str:  # noqa: N802
        return self._group_id

    def icon(self) -> QIcon:
        return QIcon(str(ICON))

    def helpUrl(self) -> str:  # noqa: N802
        return "https://github.com/soilvolume/soilvolume#readme"
