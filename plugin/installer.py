"""Installing the engine's missing dependencies from QGIS: a background task running pip into the
plugin's private folder, with progress and a log, and the message bar that offers it (once)."""

from __future__ import annotations

import importlib
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

from qgis.core import Qgis, QgsApplication, QgsMessageLog, QgsTask

from . import deps

LOG_TAG = "Soil volume change"
TITLE = "Soil volume change"


def log(message: str, level=Qgis.MessageLevel.Info) -> None:
    QgsMessageLog.logMessage(message, LOG_TAG, level)


class InstallTask(QgsTask):
    """pip installs ``requirements`` into ``target``; progress moves with each package pip
    reports, every pip line goes to the "Soil volume change" log."""

    def __init__(
        self, requirements: Sequence[str], target: Path, done: Callable[[bool, str], None] | None = None
    ) -> None:
        super().__init__("Installing the Soil volume change dependencies", QgsTask.CanCancel)
        self.commands = deps.pip_commands(requirements, target)
        self.target, self.done, self.error = target, done, ""
        self.lines: list[str] = []

    def run(self) -> bool:
        self.target.mkdir(parents=True, exist_ok=True)
        for i, command in enumerate(self.commands):
            log("Running: " + deps.shell_text(command))
            if not self._run_one(command, i):
                return False
        return True

    def _run_one(self, command: list[str], index: int) -> bool:
        share = 100.0 / len(self.commands)
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        seen = 0
        for line in proc.stdout:  # type: ignore[union-attr]
            self.lines.append(line.rstrip())
            log(line.rstrip())
            if line.startswith(("Collecting", "Installing", "Successfully")):
                seen += 1
                self.setProgress(index * share + share * (1 - 0.8**seen))
            if self.isCanceled():
                proc.terminate()
                self.error = "cancelled"
                return False
        if proc.wait() != 0:
            self.error = "\n".join(self.lines[-5:])
            return False
        return True

    def finished(self, result: bool) -> None:  # noqa: D401 - Qt API
        if result:
            deps.activate(self.target)
            importlib.invalidate_caches()
        if self.done is not None:
            self.done(result, self.error)


class DependencyBar:
    """The message bar entry shown at plugin load when dependencies are missing, once per
    session; its Install button runs :class:`InstallTask`."""

    shown = False  # once per QGIS session, however often the plugin is reloaded

    def __init__(self, iface) -> None:
        self.iface = iface
        self.task: InstallTask | None = None
        self.item = None

    def check(self) -> list[tuple[str, str, str]]:
        """Show the bar if something is missing (quick look-up, no import); returns the missing."""
        missing = deps.missing(deps.POINT_CLOUD_DEPS, quick=True)
        if missing and not DependencyBar.shown and self.iface is not None:
            DependencyBar.shown = True
            self.show(deps.missing(quick=True))  # the optional ones come along
        return missing

    def show(self, missing: Sequence[tuple[str, str, str]]) -> None:
        from qgis.PyQt.QtWidgets import QPushButton

        bar = self.iface.messageBar()
        names = ", ".join(sorted({m for m, _, _ in missing}))
        self.item = bar.createMessage(TITLE, f"needs Python packages QGIS does not have ({names}).")
        button = QPushButton("Install")
        button.setObjectName("soilvolumeInstallDependencies")
        button.clicked.connect(lambda: self.install([r for _, r, _ in missing]))
        self.item.layout().addWidget(button)
        bar.pushWidget(self.item, Qgis.MessageLevel.Warning)
        log(deps.message(missing), Qgis.MessageLevel.Warning)

    def install(self, requirements: Sequence[str]) -> InstallTask:
        """Start the install task (progress in QGIS's task manager, pip's output in the log)."""
        if self.item is not None:
            self.iface.messageBar().popWidget(self.item)
            self.item = None
        self.task = InstallTask(requirements, deps.site_dir(), self.report)
        QgsApplication.taskManager().addTask(self.task)
        self.iface.messageBar().pushMessage(
            TITLE, "Installing dependencies in the background (progress in the task bar).", Qgis.MessageLevel.Info, 5
        )
        return self.task

    def report(self, ok: bool, error: str) -> None:
        bar = self.iface.messageBar()
        still = deps.missing() if ok else []
        if ok and not still:
            bar.pushMessage(TITLE, "Dependencies installed: the algorithms are ready.", Qgis.MessageLevel.Success, 10)
        elif ok:
            bar.pushMessage(TITLE, "Dependencies installed; restart QGIS to load them.", Qgis.MessageLevel.Warning)
        else:
            bar.pushMessage(
                TITLE, f"Installing the dependencies failed (see the log): {error[-300:]}", Qgis.MessageLevel.Critical
            )
