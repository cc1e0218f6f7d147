"""Bridge to the engine package ``soilvolume``: finding it, checking its dependencies, hooks
from Processing feedback and engine errors as ``QgsProcessingException``.

Nothing here imports the engine's heavy dependencies at plugin load time (the plugin checks them
once at load and offers to install them); an algorithm that runs without them fails with one
message saying what is missing and how to install it.
"""

from __future__ import annotations

import html
import importlib
import importlib.util
import re
import sys
import traceback
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

from qgis.core import QgsProcessingException, QgsProcessingFeedback

from ..plugin import deps as deps_module

PLUGIN_DIR = Path(__file__).resolve().parent.parent
TRACKER = "https://github.com/soilvolume/soilvolume/issues"

POINT_CLOUD_DEPS = deps_module.POINT_CLOUD_DEPS
RASTER_DEPS = deps_module.RASTER_DEPS


def ensure_engine_package() -> None:
    """Make the engine importable as top-level ``soilvolume``.

    Uses an already imported or installed ``soilvolume`` if there is one, else the copy shipped
    inside the plugin folder, loaded by file location (never by putting the plugin folder on
    ``sys.path``).
    """
    if "soilvolume" in sys.modules:
        return
    bundled = PLUGIN_DIR / "soilvolume" / "__init__.py"
    if bundled.is_file():
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
        return
    importlib.import_module("soilvolume")


def engine(name: str = "api") -> ModuleType:
    """The engine module ``soilvolume.<name>``."""
    ensure_engine_package()
    return importlib.import_module(f"soilvolume.{name}")


def require(deps: Sequence[tuple[str, str]], feedback: QgsProcessingFeedback | None = None) -> None:
    """Raise QgsProcessingException naming what is missing; how to install it goes to the log
    once (the error itself is repeated by Processing's log, console and dialog)."""
    missing = deps_module.missing(deps)
    if missing:
        names = ", ".join(m for m, _, _ in missing)
        if feedback is None:
            raise QgsProcessingException(deps_module.message(missing))
        feedback.pushWarning(deps_module.message(missing))
        raise QgsProcessingException(
            f"Soil volume change cannot run: missing Python packages ({names}); "
            "how to install them is in the warning above."
        )
    try:
        engine("api")
    except Exception as exc:  # noqa: BLE001
        raise QgsProcessingException(
            f"Soil volume change cannot run: its engine package 'soilvolume' does not import "
            f"({type(exc).__name__}: {exc}). Reinstall the plugin."
        ) from exc


def hooks(feedback: QgsProcessingFeedback | None, skip: tuple[str, ...] = ()):  # -> soilvolume.api.Hooks
    """Engine hooks: progress bar, Processing log (in QGIS's wording; engine lines starting with
    one of ``skip`` left out, e.g. those the algorithm logs itself), cancel button."""
    fb = feedback or QgsProcessingFeedback()

    def log(message: str) -> None:
        if not message.startswith(skip):
            fb.pushInfo(qgis_wording(message))

    return engine("api").Hooks(
        progress=lambda percent, _message: fb.setProgress(float(percent)), log=log, cancel=fb.isCanceled
    )


def parameter_names() -> dict[str, str]:
    """``--flag`` -> "'Label' (NAME)" for every option of the engine's table."""
    from .optionparams import description, key, option_fields

    names = {"--" + f.name.replace("_", "-"): f"'{description(f)}' ({key(f)})" for f in option_fields()}
    names["--crs"] = "'CRS override' (CRS)"
    return names


def qgis_wording(message: str) -> str:
    """An engine message as a sentence naming Processing parameters instead of command-line
    flags: "--coarse fpfh forces it" -> "'Coarse registration' (COARSE) = fpfh forces it"."""
    text = reword_flags(message)
    return text[:1].upper() + text[1:]


def reword_flags(text: str) -> str:
    """``text`` with every command-line flag of the engine replaced by its parameter's label and
    name (followed by " =" when a value follows the flag); "(--flag)" and "--flag," included."""
    names = parameter_names()
    words = text.split(" ")
    for i, word in enumerate(words):
        flag = word.lstrip("(").rstrip(".,;:)")
        if flag not in names:
            continue
        lead = word[: word.index(flag)]
        tail = word[len(lead) + len(flag) :]
        words[i] = lead + names[flag] + tail
        if not tail and flag != "--crs" and i + 1 < len(words) and not words[i + 1].startswith(("-", "(")):
            words[i] += " ="
    return " ".join(words).replace("pass the '", "set the '")


def reword_html(page: str) -> str:
    """An engine HTML report with the flags in its text reworded (:func:`reword_flags`); markup,
    styles and scripts untouched."""
    parts = re.split(r"(<[^>]*>)", page)
    raw = False
    for i, part in enumerate(parts):
        if part.startswith("<"):
            tag = part[1:].split(" ", 1)[0].rstrip(">").lower()
            raw = tag in ("style", "script") or (raw and tag not in ("/style", "/script"))
        elif not raw and "--" in part:
            parts[i] = html.escape(reword_flags(html.unescape(part)), quote=False)
    return "".join(parts)


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


@contextmanager
def engine_errors(feedback: QgsProcessingFeedback | None, hint: str = "") -> Iterator[None]:
    """Engine errors become QgsProcessingException with the engine's message."""
    api = engine("api")
    try:
        yield
    except api.Cancelled as exc:
        raise QgsProcessingException("Cancelled by the user; no outputs were written.") from exc
    except engine("core.types").SoilVolumeError as exc:
        message = option_error_text(exc) or qgis_wording(str(exc))
        if hint and "crs" in message.lower() and "parameter" not in message:
            message = f"{message}\n{hint}"
        raise QgsProcessingException(message) from exc
    except QgsProcessingException:
        raise
    except MemoryError as exc:
        raise QgsProcessingException("Out of memory: use a larger cell size or crop the clouds first.") from exc
    except Exception as exc:  # noqa: BLE001 - never let an engine bug take QGIS down
        if feedback is not None:
            feedback.reportError(traceback.format_exc())
        raise QgsProcessingException(
            f"Unexpected error in the soil volume engine ({type(exc).__name__}: {exc}). "
            f"Please report it with the Processing log at {TRACKER}"
        ) from exc
