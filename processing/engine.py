"""Bridge to the engine: it runs out of process, in the plugin's own Python environment
(``plugin/environment.py``), started as ``soilvolume COMMAND ... --progress jsonl``; its progress,
log and warnings stream into the Processing feedback, Cancel stops it within a second, and its
errors become ``QgsProcessingException`` in QGIS's words (parameters, not command-line flags).

QGIS's own Python imports nothing of the engine but its option table (``soilvolume.options``,
standard library only): no numpy, pyproj, rasterio or Open3D ever loads into QGIS.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any

from qgis.core import QgsProcessingException, QgsProcessingFeedback, QgsProcessingUtils

from ..plugin import child, environment
from .optiontable import engine, option_error_text, qgis_wording

TRACKER = "https://github.com/soilvolume/soilvolume/issues"
CANCELLED = "Cancelled by the user; no outputs were written."
INSTALL_HINT = (
    "Install it with Plugins > Soil volume change > Install dependencies…, the message bar's Install "
    "button, or headless: qgis_process run soilvolume:installdependencies"
)


def ready_environment(feedback: QgsProcessingFeedback | None = None) -> environment.Environment:
    """The installed environment, or QgsProcessingException. Why not and how to install it go
    to the log once, as a warning (Processing repeats the error itself in its log, console and
    dialog); without ``feedback`` the error says it all."""
    folder = environment.env_folder()
    env = environment.load(folder)
    if env is None:
        advice = f"Soil volume change cannot run yet: {environment.status(folder)} ({folder}). {INSTALL_HINT}."
        if feedback is None:
            raise QgsProcessingException(advice)
        feedback.pushWarning(advice)
        raise QgsProcessingException(
            "Soil volume change cannot run yet: the engine's Python environment is missing or out of "
            "date; how to install it is in the warning above."
        )
    return env


def run(
    args: Sequence[str],
    feedback: QgsProcessingFeedback | None,
    skip: tuple[str, ...] = (),
    hint: str = "",
) -> dict[str, Any]:
    """Run ``soilvolume ARGS --progress jsonl`` in the environment; the result line's fields.
    Engine log lines starting with one of ``skip`` are left out (the algorithm logs them)."""
    fb = feedback or QgsProcessingFeedback()
    env = ready_environment(feedback)

    def log(message: str) -> None:
        if not message.startswith(skip):
            fb.pushInfo(qgis_wording(message))

    events = child.Events(
        progress=fb.setProgress,
        log=log,
        warning=lambda m: fb.pushWarning(qgis_wording(m)),
        debug=fb.pushDebugInfo,
        cancelled=fb.isCanceled,
    )
    try:
        return child.run_engine(env.command([*args, "--progress", "jsonl"]), engine_environ(), events)
    except child.Cancelled as exc:
        raise QgsProcessingException(CANCELLED) from exc
    except child.EngineError as exc:
        raise QgsProcessingException(error_text(exc, hint)) from exc


def engine_environ() -> dict[str, str]:
    """The engine's environment variables: QGIS's, scrubbed (``environment.child_environ``), and
    Dask's scratch space in Processing's temporary folder (QGIS removes it at exit) rather than
    the system's."""
    return environment.child_environ({"DASK_TEMPORARY_DIRECTORY": QgsProcessingUtils.tempFolder()})


def error_text(exc: child.EngineError, hint: str = "") -> str:
    """An engine error in QGIS's words; a crash with its last lines and where to report it."""
    if exc.crashed:
        return f"{exc.message}\nPlease report it with the Processing log at {TRACKER}"
    message = option_error_text(exc) or qgis_wording(exc.message)
    if hint and "crs" in message.lower() and "parameter" not in message:
        message = f"{message}\n{hint}"
    return message


def python(args: Sequence[str], feedback: QgsProcessingFeedback | None = None) -> None:
    """Run the environment's Python on ``-c CODE ARGS`` (e.g. a LAZ to LAS conversion)."""
    env = ready_environment(feedback)
    proc = child.start(env.python(list(args)), environment.child_environ())
    proc.stdin.close()
    tail: deque[str] = deque(maxlen=12)
    try:
        for _stream, line in child.lines(proc, (feedback or QgsProcessingFeedback()).isCanceled):
            tail.append(line)
    except child.Cancelled as exc:
        raise QgsProcessingException(CANCELLED) from exc
    code = child.exit_code(proc)
    if code != 0:
        raise QgsProcessingException(child.crash_text(code, tail))


def option_args(options, command: str) -> list[str]:
    """Command-line flags of the ``options`` that ``command`` takes and differ from the default."""
    out: list[str] = []
    for f in engine("options").command_fields(command):
        value = getattr(options, f.name)
        if f.name == "keep_registered_cloud" or value is None or value == f.default:
            continue
        out += ["--" + f.name.replace("_", "-"), repr(value) if isinstance(value, float) else str(value)]
    return out
