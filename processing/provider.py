"""The "Soil volume change" Processing provider."""

from __future__ import annotations

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from ..plugin import deps
from .base import ICON
from .estimatevolumechange import EstimateVolumeChange
from .pointcloudtodem import PointCloudToDem
from .registerpointclouds import RegisterPointClouds
from .volumefromdems import VolumeFromDems

PROVIDER_ID = "soilvolume"
ALGORITHMS = (EstimateVolumeChange, PointCloudToDem, RegisterPointClouds, VolumeFromDems)


class SoilVolumeProvider(QgsProcessingProvider):
    """Registers the four algorithms; the engine is imported only when one runs."""

    def loadAlgorithms(self) -> None:  # noqa: N802 - Qt API
        deps.activate()  # also when only the provider is used (qgis_process, tests)
        for algorithm in ALGORITHMS:
            self.addAlgorithm(algorithm())

    def id(self) -> str:
        return PROVIDER_ID

    def name(self) -> str:
        return "Soil volume change"

    def longName(self) -> str:  # noqa: N802
        from .. import plugin_version

        return f"Soil volume change {plugin_version()}"

    def icon(self) -> QIcon:
        return QIcon(str(ICON))

    def svgIconPath(self) -> str:  # noqa: N802
        return str(ICON)
