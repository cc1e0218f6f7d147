"""Parameter definitions and evaluation shared by the algorithms."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsMapLayer,
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingOutputFile,
    QgsProcessingOutputLayerDefinition,
    QgsProcessingParameterCrs,
    QgsProcessingParameterDefinition,
    QgsProcessingParameterFileDestination,
    QgsProcessingUtils,
    QgsProperty,
)

from . import engine, widgets
from .inputs import (
    CLOUD_EXTENSIONS,
    CloudOrSurfaceParameter,
    CloudParameter,
    is_surface_file,
)

LAS_FILTER = "LAZ files (*.laz);;LAS files (*.las)"
LAS_SUFFIXES = (".las", ".laz")


def optional_file(key: str, label: str, file_filter: str) -> QgsProcessingParameterFileDestination:
    """A file output the user asks for: optional, not created unless given a path."""
    return QgsProcessingParameterFileDestination(
        key, label, fileFilter=file_filter, optional=True, createByDefault=False
    )


RASTER_COPY_SUFFIXES = (".tif", ".tiff")


class ReportDestination(QgsProcessingParameterFileDestination):
    """An HTML report's destination whose output is a file, not an HTML output: QGIS 3.40's Batch
    dialog hands every HTML output to its Results Viewer with a call that raises a TypeError
    (``ProcessingResults.addResult() missing ... 'timestamp'``), once per row."""

    def __init__(self, name: str, description: str, file_filter: str, default: bool) -> None:
        super().__init__(name, description, fileFilter=file_filter, optional=True, createByDefault=default)

    def toOutputDefinition(self) -> QgsProcessingOutputFile:  # noqa: N802 - Qt API
        return QgsProcessingOutputFile(self.name(), self.description())

    def clone(self) -> ReportDestination:
        copy = type(self)(self.name(), self.description(), self.fileFilter(), self.createByDefault())
        copy.setHelp(self.help())
        copy.setFlags(self.flags())
        copy.setMetadata(self.metadata())
        return copy


def advanced(param: QgsProcessingParameterDefinition) -> QgsProcessingParameterDefinition:
    """Mark a parameter as advanced."""
    param.setFlags(param.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
    return param


def cloud_param(key: str, label: str, surface: bool = False) -> QgsProcessingParameterDefinition:
    """One required input per epoch: a point cloud layer, or a file path (LAS, LAZ, COPC, VPC,
    PLY, PCD, XYZ/TXT/CSV; also when QGIS itself cannot open the file as a layer); with
    ``surface`` also a raster layer or GeoTIFF (a DEM as the reference)."""
    param = (CloudOrSurfaceParameter if surface else CloudParameter)(key, f"{label} point cloud")
    param.setHelp(
        f"The {label.lower()} survey: a point cloud layer of the project or a file "
        f"({', '.join('.' + e for e in CLOUD_EXTENSIONS)})"
        + (
            "; or a surface as the reference: a single-band DEM raster layer or GeoTIFF (a grading plan or an "
            "earlier DEM) or a LandXML TIN design (.xml), against which nothing is registered (volumes "
            "above/below the design)."
            if surface
            else "."
        )
    )
    return widgets.no_default_layer(param)  # the dialog never preselects the project's first layer


def crs_param(key: str, label: str) -> QgsProcessingParameterCrs:
    return QgsProcessingParameterCrs(key, f"{label} CRS override (for a file without one)", optional=True)


def cloud_path(
    alg: QgsProcessingAlgorithm,
    parameters: dict[str, Any],
    key: str,
    context: QgsProcessingContext,
    label: str,
    surface: bool = False,
) -> str:
    """The point cloud file behind ``key``: a file path as given, or a layer's source file; with
    ``surface`` also a DEM GeoTIFF (a raster layer's source file)."""
    path = _cloud_source(alg, parameters, key, context, surface)
    if not path:
        raise QgsProcessingException(f"No {label.lower()} point cloud: choose a point cloud layer or a file.")
    if surface and is_surface_file(path):
        if not Path(path).is_file():
            raise QgsProcessingException(f"{label} surface {path}: file not found.")
        return path
    check_cloud_file(path, label)
    return path


def _cloud_source(alg, parameters: dict[str, Any], key: str, context: QgsProcessingContext, surface=False) -> str:
    value = parameters.get(key)
    if isinstance(value, QgsProperty):
        value = value.valueAsString(context.expressionContext())[0]  # (text, ok)
    if isinstance(value, QgsMapLayer):
        return value.source()
    if not value:
        return ""
    if isinstance(value, str) and Path(value).is_file():
        return value
    layer = alg.parameterAsPointCloudLayer(parameters, key, context)  # a layer of the project, by id or name
    if layer is None and surface:
        layer = alg.parameterAsRasterLayer(parameters, key, context)
    return layer.source() if layer is not None else str(value)


def unset_output(parameters: dict[str, Any], key: str) -> bool:
    """Whether a layer output was left empty (a Batch row's blank column: an output definition
    with no destination). QGIS's parameterAsOutputLayer/parameterAsSink would register "" as a
    layer to load, which Batch then reports in red as "not correctly generated"."""
    value = parameters.get(key)
    if not isinstance(value, QgsProcessingOutputLayerDefinition):
        return False  # absent or a plain string: nothing is loaded, QGIS's default applies
    sink = value.sink
    return sink.propertyType() == QgsProperty.StaticProperty and sink.staticValue() in (None, "")


def output_layer(alg: QgsProcessingAlgorithm, parameters: dict[str, Any], key: str, context) -> str:
    """The destination of a layer output, "" when it was left empty (see :func:`unset_output`)."""
    return "" if unset_output(parameters, key) else alg.parameterAsOutputLayer(parameters, key, context)


def check_cloud_file(path: str, label: str) -> None:
    """Existence and extension of a point cloud file, with a clear message."""
    p = Path(path)
    if not p.is_file():
        raise QgsProcessingException(f"{label} point cloud {path}: file not found.")
    if p.suffix.lower().lstrip(".") not in CLOUD_EXTENSIONS:
        raise QgsProcessingException(
            f"{label} point cloud {path}: unsupported file type '{p.suffix or '(none)'}'; "
            f"expected one of: {', '.join('.' + e for e in CLOUD_EXTENSIONS)}."
        )


def check_cloud_value(
    alg: QgsProcessingAlgorithm,
    parameters: dict[str, Any],
    key: str,
    context: QgsProcessingContext,
    label: str,
) -> tuple[bool, str]:
    """checkParameterValues for one cloud input: a layer, or a readable supported file (or a
    surface, where the parameter takes one)."""
    surface = isinstance(alg.parameterDefinition(key), CloudOrSurfaceParameter)
    try:
        cloud_path(alg, parameters, key, context, label, surface)
    except QgsProcessingException as exc:
        return False, str(exc)
    return True, ""


def crs_text(
    alg: QgsProcessingAlgorithm,
    parameters: dict[str, Any],
    key: str,
    context: QgsProcessingContext,
) -> str | None:
    """An optional CRS parameter as text the engine (pyproj) understands."""
    if not parameters.get(key):
        return None
    crs: QgsCoordinateReferenceSystem = alg.parameterAsCrs(parameters, key, context)
    if not crs.isValid():
        return None
    authid = crs.authid()
    if authid.upper().startswith("EPSG:"):
        return authid
    return crs.toWkt(QgsCoordinateReferenceSystem.WKT2_2019)


def to_json(value: Any, indent: int | None = None) -> str:
    """JSON of engine values (numpy arrays and scalars included)."""

    def plain(obj: Any) -> Any:
        if hasattr(obj, "tolist"):
            return obj.tolist()
        return str(obj)

    return json.dumps(value, indent=indent, default=plain)


def deliver_raster(src: Path, dest: str | None) -> str | None:
    """Move an engine GeoTIFF to a destination (converting when it is not a GeoTIFF)."""
    if not dest:
        return None
    dest_folder(Path(dest).parent)
    if Path(dest).suffix.lower() in RASTER_COPY_SUFFIXES:
        return copy(src, dest)
    from osgeo import gdal

    try:
        written = gdal.Translate(dest, str(src))
    except RuntimeError as exc:  # GDAL's exceptions on
        raise QgsProcessingException(f"Cannot write the raster {dest}: {exc}") from exc
    if written is None:
        raise QgsProcessingException(f"Cannot write the raster {dest} (unsupported format?).")
    return dest


def is_las(path: str | Path) -> bool:
    """Whether ``path`` names a LAS/LAZ file (COPC included)."""
    return Path(path).suffix.lower() in LAS_SUFFIXES


LAZ_TO_LAS = "import laspy,sys;laspy.read(sys.argv[1]).write(sys.argv[2])"


def deliver_cloud(src: Path, dest: str | None, feedback=None) -> str | None:
    """Copy an engine LAZ cloud to a destination (.laz as is, .las decompressed by the engine's
    Python: laspy never loads into QGIS)."""
    if not dest:
        return None
    dest_folder(Path(dest).parent)
    if Path(dest).suffix.lower() == src.suffix.lower():
        return copy(src, dest)
    if not is_las(dest):
        raise QgsProcessingException(f"{dest}: the registered cloud is written as .las or .laz.")
    converted = src.with_name(src.stem + "_converted.las")  # in the run's folder: no half-written dest
    engine.python(["-c", LAZ_TO_LAS, str(src), str(converted)], feedback)
    return copy(converted, dest)


@contextmanager
def work_folder() -> Iterator[Path]:
    """A private folder in Processing's temporary folder for one engine run, removed afterwards
    whatever happened (the engine writes there; outputs are copied to their destinations only
    after it succeeded, so nothing is written on cancel or failure)."""
    folder = Path(tempfile.mkdtemp(prefix="soilvolume_", dir=QgsProcessingUtils.tempFolder()))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def pair_label(before: str, after: str) -> tuple[str, str]:
    """The names a run's layers carry: the before and after files' names without suffixes."""

    def stem(path: str) -> str:
        name = Path(path).name
        for suffix in (".copc.laz", *(f".{e}" for e in CLOUD_EXTENSIONS)):
            if name.lower().endswith(suffix):
                return name[: -len(suffix)]
        return Path(path).stem

    return stem(before), stem(after)


_RUNS: dict[tuple[str, str], int] = {}  # runs of each pair in this QGIS session
_RUNS_LOCK = threading.Lock()  # Batch rows and models run in worker threads


def run_label(pair: tuple[str, str]) -> tuple[tuple[str, str], str]:
    """(the names the run's layers carry, the Layers-panel group of the run's outputs), unique to
    the run: QGIS puts outputs into an existing group of the same name, so a second run of a pair
    in a session has its number in its layers' names (``autzen_bmx_2023, run 2``) and every
    group its number and time (``Soil volume: a → b (run 2, 14:03:22)``: also unique beside the
    groups of a project saved in an earlier session)."""
    if not pair[1]:
        return pair, ""
    with _RUNS_LOCK:
        _RUNS[pair] = number = _RUNS.get(pair, 0) + 1
    group = f"Soil volume: {pair[0]} → {pair[1]} (run {number}, {time.strftime('%H:%M:%S')})"
    return (pair if number == 1 else (f"{pair[0]}, run {number}", f"{pair[1]}, run {number}")), group


def deliver_file(src: Path, dest: str | None) -> str | None:
    if not dest:
        return None
    dest_folder(Path(dest).parent)
    return copy(src, dest)


def dest_folder(folder: Path) -> Path:
    """``folder`` (and its parents) created where missing; one that cannot be made or written into is
    one message naming it (the engine has run: its outputs wait in the work folder)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise QgsProcessingException(f"Cannot write into the folder {folder}: {exc.strerror or exc}") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        raise QgsProcessingException(f"Cannot write into the folder {folder}: permission denied")
    return folder


def copy(src: Path, dest: str) -> str:
    """``src`` copied to ``dest`` whole or not at all (through a hidden partial file beside it,
    renamed into place: a full disk or a crash leaves no half-written destination)."""
    write_atomically(dest, lambda partial: shutil.copyfile(src, partial))
    return dest


def write_atomically(dest: str | Path, write) -> None:
    """``write(partial_path)``, then the partial file renamed to ``dest``; removed on failure
    (an OS error as one line naming the destination)."""
    dest = Path(dest)
    partial = dest.with_name(f".{dest.name}.partial")
    try:
        write(partial)
        os.replace(partial, dest)
    except BaseException as exc:
        partial.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise QgsProcessingException(f"Cannot write {dest}: {exc.strerror or exc}") from exc
        raise
