"""The message bar that offers to install the engine's environment (once per session) and the
install itself from the desktop: the ``soilvolume:installdependencies`` algorithm run as a
background task, so the button, the Plugins menu and ``qgis_process`` share one installer."""

from __future__ import annotations

from collections.abc import Callable

from qgis.core import (
    Qgis,
    QgsApplication,
    QgsMessageLog,
    QgsProcessingAlgRunnerTask,
    QgsProcessingContext,
    QgsProcessingFeedback,
)

from . import environment

LOG_TAG = "Soil volume change"
TITLE = "Soil volume change"
ALGORITHM = "soilvolume:installdependencies"
_RUNS: list = []  # every install of the session, with what its task refers to (never freed under it)


def log(message: str, level=Qgis.MessageLevel.Info) -> None:
    QgsMessageLog.logMessage(message, LOG_TAG, level)


class LogFeedback(QgsProcessingFeedback):
    """The installer's lines into the "Soil volume change" tab of the Log Messages panel."""

    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []
        self.errors: list[str] = []

    def pushInfo(self, info: str) -> None:  # noqa: N802 - Qt API
        self.lines.append(info)
        log(info)
        super().pushInfo(info)

    def reportError(self, error: str, fatalError: bool = False) -> None:  # noqa: N802, N803 - Qt API
        self.errors.append(error)
        log(error, Qgis.MessageLevel.Critical)
        super().reportError(error, fatalError)


class DependencyBar:
    """The message bar entry shown at plugin load when the environment is missing or stale, once
    per session; its Install button runs :meth:`install`."""

    shown = False  # once per QGIS session, however often the plugin is reloaded

    def __init__(self, iface) -> None:
        self.iface = iface
        self.task: QgsProcessingAlgRunnerTask | None = None
        self.item = None
        self._keep: tuple = ()
        self._done: Callable[[bool, str], None] | None = None

    def check(self) -> str:
        """Show the bar if the environment is not ready (a look at its stamp); returns why not."""
        why = environment.status(environment.env_folder())
        if why and not DependencyBar.shown and self.iface is not None:
            DependencyBar.shown = True
            self.show(why)
        return why

    def close(self) -> None:
        """At plugin unload: remove the bar if it is still up (its button would call into the
        unloaded plugin), so the reloaded plugin shows its own; a bar the user closed stays
        closed for the session."""
        if self.item is None or self.iface is None:
            return
        bar = self.iface.messageBar()
        if self.item in bar.items():
            bar.popWidget(self.item)
            DependencyBar.shown = False
        self.item = None

    def show(self, why: str) -> None:
        from qgis.PyQt.QtWidgets import QPushButton

        bar = self.iface.messageBar()
        self.item = bar.createMessage(TITLE, f"cannot run yet: {why} (about 800 MB from PyPI).")
        button = QPushButton("Install")
        button.setObjectName("soilvolumeInstallDependencies")
        button.clicked.connect(lambda _checked=False: self.install())  # clicked passes `checked`
        self.item.layout().addWidget(button)
        bar.pushWidget(self.item, Qgis.MessageLevel.Warning)

    def install(self, done: Callable[[bool, str], None] | None = None) -> QgsProcessingAlgRunnerTask:
        """Run the installer in the background (progress in the task bar, its lines in the log);
        the bar says the plugin is ready only when the engine's self-test passed. ``done(ready,
        error)`` is called at the end when given (a callable: never a signal's argument)."""
        done = done if callable(done) else None
        if self.item is not None:
            self.iface.messageBar().popWidget(self.item)
            self.item = None
        alg = QgsApplication.processingRegistry().createAlgorithmById(ALGORITHM)
        context, feedback = QgsProcessingContext(), LogFeedback()
        self.task = QgsProcessingAlgRunnerTask(alg, {}, context, feedback)
        self._keep = (context, feedback, alg)
        self._done = done
        _RUNS.append(self)  # the task refers to the context and feedback until QGIS deletes it
        self.task.executed.connect(self._executed)
        QgsApplication.taskManager().addTask(self.task)
        if self.iface is not None:
            self.iface.messageBar().pushMessage(
                TITLE,
                "Installing the engine's environment in the background (progress in the task bar).",
                Qgis.MessageLevel.Info,
                5,
            )
        return self.task

    def _executed(self, ok: bool, _results: dict) -> None:
        self.report(ok, self._keep[1], self._done)

    def report(self, ok: bool, feedback: LogFeedback, done=None) -> None:
        error = "" if ok else (feedback.errors or feedback.lines or ["see the log"])[-1]
        ready = ok and not environment.status(environment.env_folder())
        if done is not None:
            done(ready, error)
        if self.iface is None:
            return
        bar = self.iface.messageBar()
        if ready:
            bar.pushMessage(TITLE, "Installed and tested: the algorithms are ready.", Qgis.MessageLevel.Success, 10)
        else:
            bar.pushMessage(
                TITLE,
                f"Installing failed (the log has pip's and the engine's lines): {last_lines(error)}",
                Qgis.MessageLevel.Critical,
            )


def last_lines(text: str, lines: int = 4, limit: int = 500) -> str:
    """The end of an error for the message bar: its last few whole lines."""
    return "\n".join(text.strip().splitlines()[-lines:])[-limit:]
