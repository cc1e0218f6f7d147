"""Bridge to the engine: it runs out of process, in the plugin's own Python environment
(``plugin/environment.py``), started as ``soilvolume COMMAND ... --progress jsonl``; its progress,
log and warnings stream into the Processing feedback, Cancel stops it within a second, and its
errors become ``QgsProcessingException`` in QGIS's words (parameters, not command-line flags).

QGIS's own Python imports nothing of the engine but its option table (``soilvolume.options``,
standard library only): no numpy, pyproj, rasterio or Open3D ever loads into QGIS.
"""

from __future__ import annotations

import html
import importlib
import importlib.util
import sys
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from qgis.core import QgsProcessingException, QgsProcessingFeedback, QgsProcessingUtils

from ..plugin import child, environment

PLUGIN_DIR = Path(__file__).resolve().parent.parent
TRACKER = "https://github.com/soilvolume/soilvolume/issues"
CANCELLED = "Cancelled by the user; no outputs were written."
INSTALL_HINT = (
    "Install it with Plugins > Soil volume change > Install dependencies…, the message bar's Install "
    "button, or headless: qgis_process run soilvolume:installdependencies"
)


def ensure_engine_package() -> None:
    """Make the engine's package importable as top-level ``soilvolume`` (for its option table):
    an already imported one, else the copy shipped inside the plugin folder, loaded by file
    location (never by putting the plugin folder on ``sys.path``)."""
    if "soilvolume" in sys.modules:
        return
    bundled = PLUGIN_DIR / "soilvolume" / "__init__.py"
    spec = importlib.util.spec_from_file_location(
        "soilvolume", bundled, submodule_search_locations=[str(bundled.parent)]
    )
    if spec is None or spec.loader is None:  # pragma: no cover - defensive
        raise ImportError(f"cannot load the engine from {bundled}")
    module = importlib.util.module_from_spec(spec)
    sys.modules["soilvolume"] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules["soilvolume"]
        raise


def engine(name: str = "options") -> ModuleType:
    """A standard-library-only engine module (``options``, ``wording``): nothing else is imported here."""
    ensure_engine_package()
    return importlib.import_module(f"soilvolume.{name}")


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


def parameter_names() -> dict[str, str]:
    """Option key -> "'Label' (NAME)" for every option of the engine's table."""
    from .optionparams import description, key, option_fields

    names = {f.name: f"'{description(f)}' ({key(f)})" for f in option_fields()}
    names["crs"] = "'CRS override' (CRS)"
    return names


def parameter_name(option: str, value: str | None = None, names: dict[str, str] | None = None) -> str:
    """An option the engine names by key (``soilvolume.wording``) as its Processing parameter:
    "'Coarse registration' (COARSE)", with its value "... (COARSE) = fpfh"."""
    name = (names or parameter_names()).get(option) or engine("core.wording").flag(option)
    return name if value is None else f"{name} = {value}"


def qgis_wording(message: str) -> str:
    """An engine message (options by key) as a sentence naming Processing parameters:
    "{opt:coarse=fpfh} forces it" -> "'Coarse registration' (COARSE) = fpfh forces it"."""
    names = parameter_names()
    text = engine("core.wording").render(message, lambda k, v: parameter_name(k, v, names))
    return text[:1].upper() + text[1:]


def reword_html(page: str) -> str:
    """An engine HTML report with its options (``<span data-option>`` elements) named by their
    parameters; the rest of the page untouched."""
    names = parameter_names()
    return engine("core.wording").html_render(page, lambda k, v: html.escape(parameter_name(k, v, names), quote=False))


def option_error_text(exc: Exception) -> str | None:
    """An engine option error (it names the option's field) worded with the parameter."""
    field, reason = getattr(exc, "field", None), getattr(exc, "reason", None)
    if not field or not reason:
        return None
    from .optionparams import description, key, option_fields

    match = [f for f in option_fields() if f.name == field]
    if not match:
        return None
    return f"Incorrect parameter value for '{description(match[0])}' ({key(match[0])}): {reason}"
