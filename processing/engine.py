"""Bridge to the engine package ``soilvolume``: finding it, checking its dependencies, hooks
from Processing feedback and engine errors as ``QgsProcessingException``.

Nothing here imports the engine's heavy dependencies at plugin load time: the check runs when an
algorithm runs, so the plugin always loads and lists its algorithms.
"""

from __future__ import annotations

import importlib
import importlib.util
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


def missing_dependencies(deps: Sequence[tuple[str, str]]) -> list[tuple[str, str, str]]:
    """(module, pip requirement, error) for every dependency that does not import."""
    missing = []
    for module, requirement in deps:
        try:
            importlib.import_module(module)
        except Exception as exc:  # noqa: BLE001 - any import failure (ImportError, OSError...)
            missing.append((module, requirement, f"{type(exc).__name__}: {exc}"))
    return missing


def python_executable() -> str:
    """The Python interpreter QGIS runs (sys.executable is often the QGIS binary itself)."""
    exe = Path(sys.executable or "")
    if exe.name.lower().startswith("python"):
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


@contextmanager
def engine_errors(feedback: QgsProcessingFeedback | None, hint: str = "") -> Iterator[None]:
    """Engine errors become QgsProcessingException with the engine's message."""
    api = engine("api")
    try:
        yield
    except api.Cancelled as exc:
        raise QgsProcessingException("Cancelled by the user; no outputs were written.") from exc
    except engine("types").SoilVolumeError as exc:
        message = str(exc)
        if hint and "crs" in message.lower():
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
