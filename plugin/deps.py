"""The engine's Python dependencies: which are missing, and pip installing them into a folder of
the plugin's own, never over the packages of QGIS or of the system.

The folder is ``<QGIS settings folder>/soilvolume/site-packages`` (per profile, kept across plugin
updates). It is appended to ``sys.path`` at plugin load, after QGIS's own packages, so QGIS's
numpy, GDAL and PROJ always win; the install pins numpy to the version QGIS already uses.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from collections.abc import Sequence
from pathlib import Path

_OPEN3D_PIP = "open3d-cpu" if sys.platform.startswith("linux") else "open3d"
# (module to import, pip requirement that provides it)
POINT_CLOUD_DEPS: tuple[tuple[str, str], ...] = (
    ("numpy", "numpy"),
    ("scipy", "scipy"),
    ("pyproj", "pyproj"),
    ("rasterio", "rasterio"),
    ("laspy", "laspy[lazrs]"),
    ("lazrs", "laspy[lazrs]"),
    ("open3d", _OPEN3D_PIP),
    ("shapely", "shapely"),  # zones and stable-ground polygons (read with QGIS's own GDAL here)
)
RASTER_DEPS: tuple[tuple[str, str], ...] = (*POINT_CLOUD_DEPS[:4], ("shapely", "shapely"))
# Not needed to run, offered with the rest: surveys past the memory budget run as Dask tasks
# (without it, the Scheduler "auto" runs them in-process).
OPTIONAL_DEPS: tuple[tuple[str, str], ...] = (("distributed", "dask[distributed]"),)
ALL_DEPS = POINT_CLOUD_DEPS + OPTIONAL_DEPS
# open3d's own requirements are mostly its notebook viewer's (ipywidgets, nbformat, ipython, ...);
# the engine uses only its numpy core, so it is installed without them, plus dash, which its
# ``import open3d`` needs (open3d.visualization imports it).
NO_DEPS = {"open3d", "open3d-cpu"}
NO_DEPS_NEEDS = ("dash",)


def site_dir() -> Path:
    """The plugin-private folder the dependencies are installed into."""
    from qgis.core import QgsApplication

    return Path(QgsApplication.qgisSettingsDirPath()) / "soilvolume" / "site-packages"


def activate(folder: Path | None = None) -> Path:
    """Append the private folder to ``sys.path`` if it exists. Its .pth files are not run: one
    from setuptools (pulled in by a dependency) would patch distutils for all of QGIS."""
    folder = folder or site_dir()
    if folder.is_dir() and str(folder) not in sys.path:
        sys.path.append(str(folder))
        importlib.invalidate_caches()
    return folder


def _import(module: str):
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


def missing(
    deps: Sequence[tuple[str, str]] = ALL_DEPS,
    *,
    quick: bool = False,
) -> list[tuple[str, str, str]]:
    """(module, pip requirement, error) of every dependency that does not import. ``quick``
    only looks the modules up (no import: cheap enough for plugin load)."""
    out = []
    for module, requirement in deps:
        try:
            if quick:
                if importlib.util.find_spec(module) is None:  # also None when blocked in sys.modules
                    raise ImportError(f"No module named '{module}'")
            else:
                _import(module)
        except Exception as exc:  # noqa: BLE001 - any import failure (ImportError, OSError...)
            out.append((module, requirement, f"{type(exc).__name__}: {exc}"))
    return out


def python_executable() -> str:
    """The Python interpreter behind QGIS's Python. In embedded Python ``sys.executable`` is
    often the QGIS binary, so it is trusted only when it is a python under ``sys.prefix``."""
    exe = Path(sys.executable or "")
    prefixes = {Path(sys.prefix), Path(sys.exec_prefix)}
    if exe.name.lower().startswith("python") and any(p in exe.parents for p in prefixes):
        return str(exe)
    prefix, v = Path(sys.exec_prefix), sys.version_info
    if sys.platform == "win32":
        candidates = [prefix / "python.exe", prefix / "python3.exe"]
    else:
        candidates = [prefix / "bin" / f"python{v.major}.{v.minor}", prefix / "bin" / "python3"]
    return next((str(c) for c in candidates if c.is_file()), "python3")


def _installed_numpy() -> str | None:
    try:
        import numpy
    except Exception:  # noqa: BLE001
        return None
    return numpy.__version__


def constraints_file(target: Path) -> Path | None:
    """A pip constraints file next to ``target`` pinning numpy to the version QGIS already
    uses (its compiled modules need that ABI): numpy is installed only if a package needs it, and
    then in that version. None when QGIS has no numpy."""
    numpy = _installed_numpy()
    if numpy is None:
        return None
    path = target.parent / "constraints.txt"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"numpy=={numpy}\n", encoding="utf-8")
    return path


def pip_commands(requirements: Sequence[str], target: Path) -> list[list[str]]:
    """The pip runs that install ``requirements`` into ``target``: the rest, numpy constrained to
    QGIS's own, then open3d without its dependencies (writes the constraints file)."""
    reqs = list(dict.fromkeys(requirements))
    alone = [r for r in reqs if r in NO_DEPS]
    rest = [r for r in reqs if r not in NO_DEPS and r != "numpy"] + (list(NO_DEPS_NEEDS) if alone else [])
    if "numpy" in reqs and _installed_numpy() is None:
        rest.append("numpy")
    base = [
        python_executable(),
        "-m",
        "pip",
        "install",
        "--disable-pip-version-check",
        "--no-input",
        "--only-binary=:all:",
        "--upgrade",
        "--target",
        str(target),
    ]
    constraints = constraints_file(target)
    if constraints is not None:
        base += ["--constraint", str(constraints)]
    commands = [base + rest] if rest else []
    if alone:
        commands.append(base + ["--no-deps"] + alone)
    return commands


def shell_text(command: Sequence[str]) -> str:
    """A command as one line to paste into a shell."""
    return " ".join(f'"{a}"' if any(c in a for c in " []<>=") else a for a in command)


def message(missing_deps: Sequence[tuple[str, str, str]]) -> str:
    """What is missing and how to install it (the plugin's Install button, or by hand)."""
    names = ", ".join(m for m, _, _ in missing_deps)
    lines = [
        f"Soil volume change cannot run: the Python used by QGIS ({python_executable()}, "
        f"Python {sys.version.split()[0]}) cannot import {names}."
    ]
    lines += [f"  - {module}: {error}" for module, _, error in missing_deps]
    lines.append(
        "In QGIS, press Install in the message bar that appears when the plugin loads "
        "(Plugins > Soil volume change > Install dependencies), or run:"
    )
    reqs = [req for _, req, _ in missing_deps]
    lines += ["  " + shell_text(c) for c in pip_commands(reqs, site_dir())]
    if sys.platform == "win32":
        lines.append("(in the OSGeo4W Shell)")
    return "\n".join(lines)
