"""The "Soil volume change" Processing provider."""

from __future__ import annotations

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from .. import plugin_version
from .base import ICON
from .estimatevolumechange import EstimateVolumeChange
from .installdependencies import InstallDependencies
from .pointcloudtodem import PointCloudToDem
from .registerpointclouds import RegisterPointClouds
from .stockpilevolumes import StockpileVolumes
from .volumefromdems import VolumeFromDems
from .volumeseries import VolumeSeries

PROVIDER_ID = "soilvolume"
ALGORITHMS = (
    EstimateVolumeChange,
    VolumeSeries,
    PointCloudToDem,
    RegisterPointClouds,
    VolumeFromDems,
    StockpileVolumes,
    InstallDependencies,
)


class SoilVolumeProvider(QgsProcessingProvider):
    """Registers the algorithms; each runs the engine in its own environment."""

    def loadAlgorithms(self) -> None:  # noqa: N802 - Qt API
        for algorithm in ALGORITHMS:
            self.addAlgorithm(algorithm())

    def id(self) -> str:
        return PROVIDER_ID

    def name(self) -> str:
        return "Soil volume change"

    def longName(self) -> str:  # noqa: N802
        return f"Soil volume change {plugin_version()}"

    def icon(self) -> QIcon:
        return QIcon(str(ICON))

    def svgIconPath(self) -> str:  # noqa: N802
        return str(ICON)
