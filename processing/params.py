"""Parameter definitions and evaluation shared by the algorithms."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingParameterCrs,
    QgsProcessingParameterDefinition,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFile,
    QgsProcessingParameterNumber,
    QgsProcessingParameterPointCloudLayer,
)

CLOUD_EXTENSIONS = ("las", "laz", "vpc", "ply", "pcd", "xyz", "txt", "csv")  # .copc.laz is a .laz
CLOUD_FILTER = (
    "Point clouds (" + " ".join(f"*.{e}" for e in CLOUD_EXTENSIONS) + ");;All files (*.*)"
)
LAS_FILTER = "LAZ files (*.laz);;LAS files (*.las)"
RASTER_COPY_SUFFIXES = (".tif", ".tiff")

FINE_METHODS = ("icp", "gicp", "pfh", "none")
FINE_LABELS = (
    "Robust ICP, point-to-plane (recommended)",
    "Generalized ICP",
    "PFH + SAC-IA on a patch (the paper's method)",
    "None (coarse registration only)",
)
COARSE_METHODS = ("auto", "fpfh", "none")
COARSE_LABELS = (
    "Auto: FPFH + RANSAC, kept only if better than the GPS pose",
    "Always FPFH + RANSAC",
    "None (trust the GPS georeferencing)",
)
CORRECTIONS = ("surface", "plane", "paper-plane", "none")
CORRECTION_LABELS = (
    "Surface: degree-2 polynomial on stable ground (recommended)",
    "Plane on stable ground",
    "Paper: two RANSAC planes, offset d_i",
    "None (no plane-offset compensation)",
)
STATISTICS = ("robust-mean", "mean", "median")
STATISTIC_LABELS = ("Robust mean (3 MAD rejection)", "Mean (the paper)", "Median")
GROUNDS = ("auto", "class", "filter", "none")
GROUND_LABELS = (
    "Auto: class 2 when the file has it, else all points",
    "Class 2 (ground) only",
    "SMRF ground filter",
    "All points",
)


def advanced(param: QgsProcessingParameterDefinition) -> QgsProcessingParameterDefinition:
    """Mark a parameter as advanced."""
    param.setFlags(param.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
    return param


def cloud_params(key: str, label: str) -> list[QgsProcessingParameterDefinition]:
    """A point cloud file parameter and its optional point cloud layer alternative."""
    return [
        QgsProcessingParameterFile(
            key, f"{label} point cloud file (LAS, LAZ, COPC, VPC, PLY, PCD, XYZ/TXT/CSV)",
            behavior=QgsProcessingParameterFile.File, fileFilter=CLOUD_FILTER, optional=True,
        ),
        QgsProcessingParameterPointCloudLayer(
            f"{key}_LAYER", f"…or a {label.lower()} point cloud layer (used when no file is given)",
            optional=True,
        ),
    ]


def crs_param(key: str, label: str) -> QgsProcessingParameterCrs:
    return QgsProcessingParameterCrs(
        key, f"{label} CRS override (when the file has none or a wrong one)", optional=True
    )


def enum_param(key: str, label: str, labels: tuple[str, ...], default: int = 0):
    return QgsProcessingParameterEnum(key, label, options=list(labels), defaultValue=default)


def number_param(key: str, label: str, default: float, minimum: float = 0.0):
    return QgsProcessingParameterNumber(
        key, label, type=QgsProcessingParameterNumber.Double, defaultValue=default,
        minValue=minimum,
    )


def cloud_path(
    alg: QgsProcessingAlgorithm, parameters: dict[str, Any], key: str,
    context: QgsProcessingContext,
    label: str,
) -> str:
    """The point cloud file behind ``key`` (a file) or ``key_LAYER`` (a point cloud layer)."""
    path = alg.parameterAsFile(parameters, key, context) if parameters.get(key) else ""
    if not path and parameters.get(f"{key}_LAYER"):
        layer = alg.parameterAsPointCloudLayer(parameters, f"{key}_LAYER", context)
        if layer is not None:
            path = layer.source()
    if not path:
        raise QgsProcessingException(f"No {label} point cloud: give a file or a point cloud layer.")
    check_cloud_file(path, label)
    return path


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


def check_clouds(parameters: dict[str, Any], keys: dict[str, str]) -> tuple[bool, str]:
    """checkParameterValues helper: each cloud given once, as a readable supported file."""
    for key, label in keys.items():
        value = parameters.get(key)
        if not value and not parameters.get(f"{key}_LAYER"):
            return False, f"No {label} point cloud: give a file or a point cloud layer."
        if isinstance(value, str) and value:
            try:
                check_cloud_file(value, label)
            except QgsProcessingException as exc:
                return False, str(exc)
    return True, ""


def crs_text(
    alg: QgsProcessingAlgorithm, parameters: dict[str, Any], key: str,
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


def qgs_crs(text: str | None) -> QgsCoordinateReferenceSystem:
    """A QGIS CRS from an authority id or WKT (invalid when empty or not understood)."""
    if not text:
        return QgsCoordinateReferenceSystem()
    crs = QgsCoordinateReferenceSystem(text)
    return crs if crs.isValid() else QgsCoordinateReferenceSystem.fromWkt(text)


def optional_cell(value: float) -> float | None:
    """Cell size parameter: 0 means automatic."""
    return float(value) if value and value > 0 else None


def deliver_raster(src: Path, dest: str | None) -> str | None:
    """Move an engine GeoTIFF to a destination (converting when it is not a GeoTIFF)."""
    if not dest:
        return None
    Path(dest).parent.mkdir(parents=True, exist_ok=True)
    if Path(dest).suffix.lower() in RASTER_COPY_SUFFIXES:
        shutil.copyfile(src, dest)
        return dest
    from osgeo import gdal

    if gdal.Translate(dest, str(src)) is None:
        raise QgsProcessingException(f"Cannot write the raster {dest} (unsupported format?).")
    return dest


def deliver_cloud(src: Path, dest: str | None) -> str | None:
    """Copy an engine LAZ cloud to a destination (.laz as is, .las decompressed)."""
    if not dest:
        return None
    Path(dest).parent.mkdir(parents=True, exist_ok=True)
    if Path(dest).suffix.lower() == src.suffix.lower():
        shutil.copyfile(src, dest)
        return dest
    if Path(dest).suffix.lower() not in (".las", ".laz"):
        raise QgsProcessingException(f"{dest}: the registered cloud is written as .las or .laz.")
    import laspy

    laspy.read(str(src)).write(dest)
    return dest


def deliver_file(src: Path, dest: str | None) -> str | None:
    if not dest:
        return None
    Path(dest).parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dest)
    return dest
