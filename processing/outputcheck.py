"""Every output a run will write, checked before any work (the engine runs for minutes): its folder
can be made and written into, no folder stands where the file goes, and a file it replaces can be
replaced; the first that cannot is one ``QgsProcessingException`` naming it and why.

On Windows a file open in QGIS (a layer of the project: GDAL keeps its file open) cannot be
replaced ("Access is denied" from ``os.replace``), nor a read-only one; :data:`LOCKS_OPEN_FILES`
says whether this system is such (tests set it to simulate Windows here).
"""

from __future__ import annotations

import os
import re
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from qgis.core import (
    QgsProcessing,
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingOutputLayerDefinition,
    QgsProcessingParameterFolderDestination,
    QgsProject,
    QgsProperty,
)

LOCKS_OPEN_FILES = sys.platform == "win32"  # an open file cannot be replaced (the seam tests set)
PROVIDER_URI = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]+:(?![\\/])")  # memory:, ogr:, postgres:... (not C:\)


def check_outputs(alg: QgsProcessingAlgorithm, parameters: dict[str, Any], context: QgsProcessingContext) -> None:
    """Raise ``QgsProcessingException`` for the first destination of the run that cannot be written."""
    for label, path, is_folder in destinations(alg, parameters, context):
        problem = folder_problem(path if is_folder else path.parent)
        if problem is None:
            problem = folder_files_problem(path, context) if is_folder else file_problem(path, context)
        if problem:
            raise QgsProcessingException(f"{label}: {problem}; nothing was computed.")


def destinations(alg, parameters: dict[str, Any], context: QgsProcessingContext) -> Iterator[tuple[str, Path, bool]]:
    """(the parameter's description, the path, whether it is a folder) of each file destination given."""
    for param in alg.destinationParameterDefinitions():
        path = destination_path(parameters.get(param.name()), context)
        if path:
            yield param.description(), Path(path), isinstance(param, QgsProcessingParameterFolderDestination)


def destination_path(value: Any, context: QgsProcessingContext) -> str:
    """A destination's file path, "" for none, a temporary output or a provider's URI."""
    if isinstance(value, QgsProcessingOutputLayerDefinition):
        value = value.sink
    if isinstance(value, QgsProperty):
        value = value.valueAsString(context.expressionContext())[0]  # (text, ok)
    if not isinstance(value, str) or not value.strip() or value == QgsProcessing.TEMPORARY_OUTPUT:
        return ""
    return "" if PROVIDER_URI.match(value) else value


def folder_problem(folder: Path) -> str | None:
    """Why ``folder`` cannot be made or written into, or None."""
    existing = folder
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    if not existing.is_dir():
        return f"cannot write into the folder {folder}: {existing} is a file, not a folder"
    if not os.access(existing, os.W_OK | os.X_OK) or not _can_create(existing):
        return f"cannot write into the folder {folder}: permission denied" + (
            "" if existing == folder else f" in {existing}"
        )
    return None


def _can_create(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (a hidden probe, removed at once)."""
    try:
        handle, probe = tempfile.mkstemp(prefix=".soilvolume-probe-", dir=folder)
    except OSError:
        return False
    os.close(handle)
    Path(probe).unlink(missing_ok=True)
    return True


def file_problem(path: Path, context: QgsProcessingContext) -> str | None:
    """Why the file at ``path`` cannot be replaced, or None."""
    if path.name in ("", ".", "..") or path.is_dir():
        return f"{path} is a folder; give a file name"
    if not path.exists() or not LOCKS_OPEN_FILES:
        return None
    layer = loaded_layer(path, context)
    if layer:
        return (
            f"cannot replace {path}: it is open in QGIS as the layer '{layer}'; remove that layer from the "
            "project (or choose another file), then run again"
        )
    if not os.access(path, os.W_OK):
        return f"cannot replace {path}: the file is read-only"
    return None


def folder_files_problem(folder: Path, context: QgsProcessingContext) -> str | None:
    """Why a file of an output folder (whose files the run replaces) cannot be replaced, or None."""
    if not LOCKS_OPEN_FILES or not folder.is_dir():
        return None
    for source, name in layer_files(context):
        if source.parent == _normal(folder):
            return (
                f"cannot replace the files in {folder}: {source.name} is open in QGIS as the layer '{name}'; "
                "remove that layer from the project (or choose another folder), then run again"
            )
    return None


def loaded_layer(path: Path, context: QgsProcessingContext) -> str:
    """The name of a layer of the project whose file is ``path`` ("" for none)."""
    target = _normal(path)
    return next((name for source, name in layer_files(context) if source == target), "")


def layer_files(context: QgsProcessingContext) -> Iterator[tuple[Path, str]]:
    """(its file, normalised; its name) of each layer of the project with a file."""
    projects = {id(p): p for p in (context.project(), QgsProject.instance()) if p is not None}
    for project in projects.values():
        for layer in project.mapLayers().values():
            source = layer.source().split("|")[0]
            if source and Path(source).is_file():
                yield _normal(Path(source)), layer.name()


def _normal(path: Path) -> Path:
    return Path(os.path.normcase(str(path.resolve())))
