"""Bridge to the engine package ``soilvolume``: finding it, checking its dependencies, hooks
from Processing feedback and engine errors as ``QgsProcessingException``.

Nothing here imports the engine's heavy dependencies at plugin load time: the check runs when an
algorithm runs, so the plugin always loads and lists its algorithms.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
import sysconfig
import traceback
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

from qgis.core import QgsProcessingException, QgsProcessingFeedback

PLUGIN_DIR = Path(__file__).resolve().parent.parent
TRACKER = "https://github.com/soilvolume/soilvolume/issues"

# (module to import, pip requirement that provides it)
_OPEN3D_PIP = "open3d-cpu" if sys.platform.startswith("linux") else "open3d"
POINT_CLOUD_DEPS: tuple[tuple[str, str], ...] = (
    ("numpy", "numpy"),
    ("scipy", "scipy"),
    ("pyproj", "pyproj"),
    ("rasterio", "rasterio"),
    ("laspy", "laspy[lazrs]"),
    ("lazrs", "laspy[lazrs]"),
    ("open3d", _OPEN3D_PIP),
)
RASTER_DEPS: tuple[tuple[str, str], ...] = (
    ("numpy", "numpy"),
    ("scipy", "scipy"),
    ("pyproj", "pyproj"),
    ("rasterio", "rasterio"),
)


def _ensure_engine_package() -> None:
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
    _ensure_engine_package()
    return importlib.import_module(f"soilvolume.{name}")


def _import(module: str) -> ModuleType:
    """Import a dependency; pyproj with RTLD_DEEPBIND on Linux (see below)."""
    if module == "pyproj" and "pyproj" not in sys.modules and hasattr(os, "RTLD_DEEPBIND"):
        # pyproj wheels bundle their own libproj. Inside QGIS, which already loaded the system
        # libproj, the bundled copy's symbols would bind to the system one; both sets of static
        # objects then get destroyed at exit and qgis_process/QGIS segfaults after a successful
        # run. Deep binding keeps the bundled libproj self-contained.
        flags = sys.getdlopenflags()
        sys.setdlopenflags(flags | os.RTLD_DEEPBIND)
        try:
            return importlib.import_module("pyproj")
        finally:
            sys.setdlopenflags(flags)
    return importlib.import_module(module)


def missing_dependencies(deps: Sequence[tuple[str, str]]) -> list[tuple[str, str, str]]:
    """(module, pip requirement, error) for every dependency that does not import."""
    missing = []
    for module, requirement in deps:
        try:
            _import(module)
        except Exception as exc:  # noqa: BLE001 - any import failure (ImportError, OSError...)
            missing.append((module, requirement, f"{type(exc).__name__}: {exc}"))
    return missing


def python_executable() -> str:
    """The Python interpreter behind QGIS's Python. In embedded Python ``sys.executable`` is
    often the QGIS binary or whatever ``python3`` is first on PATH, so it is trusted only when it
    lives under ``sys.prefix``; else the interpreter in ``sys.exec_prefix`` is named."""
    exe = Path(sys.executable or "")
    prefixes = {Path(sys.prefix), Path(sys.exec_prefix)}
    if exe.name.lower().startswith("python") and any(p in exe.parents for p in prefixes):
        return str(exe)
    prefix = Path(sys.exec_prefix)
    v = sys.version_info
    if sys.platform == "win32":
        candidates = [prefix / "python.exe", prefix / "python3.exe"]
    else:
        candidates = [prefix / "bin" / f"python{v.major}.{v.minor}", prefix / "bin" / "python3"]
    for candidate in candidates:
        if candidate.is_file():
            return str(candidate)
    return "python3"


def install_command(requirements: Sequence[str]) -> str:
    """The pip command that installs ``requirements`` into QGIS's Python."""
    reqs = list(dict.fromkeys(requirements))
    try:
        import numpy

        if int(numpy.__version__.split(".")[0]) < 2 and "numpy" not in reqs:
            reqs.append("numpy<2")  # keep the ABI of QGIS's own compiled modules
    except Exception:  # noqa: BLE001
        pass
    args = [python_executable(), "-m", "pip", "install"]
    in_venv = sys.prefix != sys.base_prefix
    if not in_venv:
        args.append("--user")
        if (Path(sysconfig.get_path("stdlib")) / "EXTERNALLY-MANAGED").exists():
            args.append("--break-system-packages")
    args += [f'"{r}"' if any(c in r for c in "[]<>") else r for r in reqs]
    return " ".join(args)


def dependency_message(missing: Sequence[tuple[str, str, str]]) -> str:
    """What is missing, why, and the exact command that installs it."""
    lines = [
        "Soil volume change cannot run: the Python used by QGIS "
        f"({python_executable()}, Python {sys.version.split()[0]}) cannot import "
        + ", ".join(m for m, _, _ in missing) + ".",
    ]
    lines += [f"  - {module}: {error}" for module, _, error in missing]
    lines += [
        "Install them with:",
        "  " + install_command([req for _, req, _ in missing]),
    ]
    if sys.platform == "win32":
        lines.append("(run it in the OSGeo4W Shell, as administrator for an all-users install)")
    lines.append("then restart QGIS.")
    return "\n".join(lines)


def require(deps: Sequence[tuple[str, str]]) -> None:
    """Raise QgsProcessingException naming what is missing and how to install it."""
    missing = missing_dependencies(deps)
    if not missing:
        try:
            engine("api")
        except Exception as exc:  # noqa: BLE001
            raise QgsProcessingException(
                f"Soil volume change cannot run: its engine package 'soilvolume' does not import "
                f"({type(exc).__name__}: {exc}). Reinstall the plugin."
            ) from exc
        return
    raise QgsProcessingException(dependency_message(missing))


def hooks(feedback: QgsProcessingFeedback | None):  # -> soilvolume.api.Hooks
    """Engine hooks: progress bar, Processing log, cancel button."""
    fb = feedback or QgsProcessingFeedback()
    return engine("api").Hooks(
        progress=lambda percent, _message: fb.setProgress(float(percent)),
        log=fb.pushInfo,
        cancel=fb.isCanceled,
    )


# the engine's messages name command-line options; say which Processing parameter instead
CLI_TO_PARAMETER = {
    "--before-crs": "the 'Before CRS override' parameter",
    "--after-crs": "the 'After CRS override' parameter",
    "--radius": "the 'Crop radius' parameter",
    "--cell": "the 'Cell size' parameter",
    "--fine": "the 'Fine registration' parameter",
    "--coarse": "the 'Coarse registration' parameter",
    "--correction": "the 'Plane-offset correction' parameter",
    "--ground": "the 'Ground points' parameter",
    "--statistic": "the 'Cell height statistic' parameter",
    "--crs": "the 'CRS override' parameter",
}


def qgis_wording(message: str) -> str:
    """An engine message with command-line options replaced by parameter names."""
    for flag in sorted(CLI_TO_PARAMETER, key=len, reverse=True):
        message = re.sub(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", CLI_TO_PARAMETER[flag], message)
    return message.replace("pass the '", "set the '")


@contextmanager
def engine_errors(feedback: QgsProcessingFeedback | None, hint: str = "") -> Iterator[None]:
    """Engine errors become QgsProcessingException with the engine's message."""
    api = engine("api")
    try:
        yield
    except api.Cancelled as exc:
        raise QgsProcessingException("Cancelled by the user; no outputs were written.") from exc
    except engine("types").SoilVolumeError as exc:
        message = qgis_wording(str(exc))
        if hint and "crs" in message.lower() and "parameter" not in message:
            message = f"{message}\n{hint}"
        raise QgsProcessingException(message) from exc
    except QgsProcessingException:
        raise
    except MemoryError as exc:
        raise QgsProcessingException(
            "Out of memory: use a larger cell size or crop the clouds first."
        ) from exc
    except Exception as exc:  # noqa: BLE001 - never let an engine bug take QGIS down
        if feedback is not None:
            feedback.reportError(traceback.format_exc())
        raise QgsProcessingException(
            f"Unexpected error in the soil volume engine ({type(exc).__name__}: {exc}). "
            f"Please report it with the Processing log at {TRACKER}"
        ) from exc
