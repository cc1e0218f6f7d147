"""Common base of the plugin's algorithms."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import QgsProcessingAlgorithm, QgsProcessingContext, QgsProcessingFeedback
from qgis.PyQt.QtCore import QCoreApplication
from qgis.PyQt.QtGui import QIcon

from . import outputcheck, params, resultsviewer

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
    _clouds: dict[str, str] = {}  # point cloud inputs: parameter -> label ("Before", ...)

    def name(self) -> str:
        return self._name

    def displayName(self) -> str:  # noqa: N802 - Qt API
        return self.tr(self._display_name)

    def shortHelpString(self) -> str:  # noqa: N802
        """The help as flowing HTML: the source's line breaks are not paragraph breaks."""
        return " ".join(self.tr(self._help).split())

    def checkParameterValues(  # noqa: N802
        self, parameters: dict[str, Any], context: QgsProcessingContext
    ) -> tuple[bool, str]:
        """QGIS's checks, except that a point cloud input may also be a file QGIS itself
        cannot open as a layer (no PDAL); a missing or unsupported file is named clearly."""
        for key, label in self._clouds.items():
            ok, message = params.check_cloud_value(self, parameters, key, context, label)
            if not ok:
                return ok, message
        for param in self.parameterDefinitions():
            if param.name() in self._clouds or param.isDestination():
                continue
            if not param.checkValueIsAcceptable(parameters.get(param.name()), context):
                return False, f"Incorrect parameter value for {param.description()}"
        return True, ""

    def check_outputs(self, parameters: dict[str, Any], context: QgsProcessingContext) -> None:
        """Every output checked writable before any work (:mod:`.outputcheck`)."""
        outputcheck.check_outputs(self, parameters, context)

    def postProcessAlgorithm(  # noqa: N802 - Qt API
        self, context: QgsProcessingContext, feedback: QgsProcessingFeedback
    ) -> dict[str, Any]:
        """After the run, in QGIS's main thread: the HTML report (``self.report``, set by the run)
        listed in the Results Viewer."""
        resultsviewer.list_report(self, getattr(self, "report", None))
        return {}

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
