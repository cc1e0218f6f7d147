"""A Processing feedback that keeps what the algorithm reported (progress, infos, warnings)."""

from __future__ import annotations

from qgis.core import QgsProcessingFeedback


class RecordingFeedback(QgsProcessingFeedback):
    def __init__(self) -> None:
        super().__init__()
        self.progress: list[float] = []
        self.infos: list[str] = []
        self.warnings: list[str] = []
        self.debug: list[str] = []
        self.errors: list[str] = []
        self.progressChanged.connect(self.progress.append)

    def pushInfo(self, info: str) -> None:  # noqa: N802 - Qt API
        self.infos.append(info)
        super().pushInfo(info)

    def pushWarning(self, warning: str) -> None:  # noqa: N802 - Qt API
        self.warnings.append(warning)
        super().pushWarning(warning)

    def pushDebugInfo(self, info: str) -> None:  # noqa: N802 - Qt API
        self.debug.append(info)
        super().pushDebugInfo(info)

    def reportError(self, error: str, fatalError: bool = False) -> None:  # noqa: N802, N803 - Qt API
        self.errors.append(error)
        super().reportError(error, fatalError)
