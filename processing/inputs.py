"""The point cloud (and surface) inputs: file-typed for Model Builder, a layer dropdown in the dialog,
file pickers that open on point clouds, and their values written as paths."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    Qgis,
    QgsPointCloudLayer,
    QgsProcessingContext,
    QgsProcessingParameterFile,
    QgsProcessingParameterMapLayer,
    QgsProcessingParameterMultipleLayers,
    QgsProperty,
    QgsRasterLayer,
)

CLOUD_EXTENSIONS = ("las", "laz", "vpc", "ply", "pcd", "xyz", "txt", "csv")  # .copc.laz is a .laz
# a surface as the reference (BEFORE of the estimate): a DEM GeoTIFF or a LandXML TIN
SURFACE_EXTENSIONS = ("tif", "tiff", "xml", "landxml")
CLOUD_FILTERS = (
    "Point clouds (" + " ".join(f"*.{e} *.{e.upper()}" for e in CLOUD_EXTENSIONS) + ")",
    "LAS/LAZ (*.las *.laz *.LAS *.LAZ)",
    "PLY (*.ply *.PLY)",
    "XYZ text (*.xyz *.txt *.csv)",
    "All files (*.*)",
)
CLOUD_FILTER = ";;".join(CLOUD_FILTERS)
SURFACE_FILTER = "DEM GeoTIFF (a surface as the reference) (*.tif *.tiff *.TIF *.TIFF)"
LANDXML_FILTER = "LandXML design (*.xml *.landxml *.XML *.LANDXML)"
# the estimate's BEFORE: point clouds first (a file dialog opens on its first filter), the designs second
CLOUD_OR_SURFACE_FILTER = ";;".join((CLOUD_FILTERS[0], SURFACE_FILTER, LANDXML_FILTER, *CLOUD_FILTERS[1:]))


def file_value(value: Any) -> str | None:
    """``value`` when it names a point cloud, GeoTIFF or LandXML file (by its extension), else None."""
    if isinstance(value, str) and Path(value).suffix.lower().lstrip(".") in CLOUD_EXTENSIONS + SURFACE_EXTENSIONS:
        return value
    return None


class CloudParameter(QgsProcessingParameterFile):
    """A survey input: a point cloud file (LAS, LAZ, COPC, VPC, PLY, PCD, XYZ) or a point cloud
    layer of the project. Typed as a file, so Model Builder offers File (and String) inputs for it,
    whose models run in the dialog and in qgis_process also where QGIS has no PDAL provider and
    cannot open a LAS/LAZ file as a layer (a Point Cloud or Map Layer input of a model is checked by
    loading it as a layer, which then fails); the algorithm dialog still offers the project's
    layers (:meth:`dropdown`, see ``widgets.no_default_layer``). Its paths are written as they are
    in the log, the history and the Python and qgis_process commands (a layer parameter tries to
    open a path as a vector, raster, mesh and point cloud layer to describe it: "Cannot open
    ....las" from OGR in the log and "Unable to load mesh (null)" from MDAL, for every input)."""

    FILTER = CLOUD_FILTER
    LAYER_TYPES: tuple = (Qgis.ProcessingSourceType.PointCloud,)
    LAYERS: tuple = (QgsPointCloudLayer,)

    def __init__(self, name: str, description: str, default: Any = None, optional: bool = False) -> None:
        super().__init__(name, description, Qgis.ProcessingFileParameterBehavior.File, "", default, optional)
        self.setFileFilter(self.FILTER)

    def createFileFilter(self) -> str:  # noqa: N802 - Qt API
        return self.FILTER

    def clone(self) -> CloudParameter:
        copy = type(self)(self.name(), self.description(), self.defaultValue(), self.flags() & self.FlagOptional)
        copy.setHelp(self.help())
        copy.setFlags(self.flags())
        copy.setMetadata(self.metadata())
        return copy

    def checkValueIsAcceptable(self, value: Any, context: QgsProcessingContext | None = None) -> bool:  # noqa: N802
        """A layer of the accepted kinds, a path, a layer's id or name, or an expression; whether a
        file is there and readable is the algorithm's check, which names it."""
        if isinstance(value, self.LAYERS) or isinstance(value, QgsProperty):
            return True
        if isinstance(value, str) and value.strip():
            return True
        return bool(self.flags() & self.FlagOptional) and value in (None, "")

    def dropdown(self) -> QgsProcessingParameterMapLayer:
        """The algorithm dialog's dropdown: the project's layers of the accepted kinds, its file
        button opening on this parameter's file filter."""
        return LayerChoice(self.name(), self.description(), list(self.LAYER_TYPES), self.FILTER)


class CloudOrSurfaceParameter(CloudParameter):
    """The estimate's BEFORE: a point cloud, or a surface as the reference (a single-band DEM:
    a raster layer or a GeoTIFF, e.g. a grading plan, or a LandXML TIN file), against which nothing is registered; the
    dialog's dropdown lists the project's point cloud and raster layers."""

    FILTER = CLOUD_OR_SURFACE_FILTER
    LAYER_TYPES = (Qgis.ProcessingSourceType.PointCloud, Qgis.ProcessingSourceType.Raster)
    LAYERS = (QgsPointCloudLayer, QgsRasterLayer)


class LayerChoice(QgsProcessingParameterMapLayer):
    """An optional map-layer parameter of the given kinds whose file button uses ``file_filter``
    (only the dialog's dropdown is built on it)."""

    def __init__(self, name: str, description: str, types: list, file_filter: str) -> None:
        super().__init__(name, description, None, True, types)
        self.file_filter = file_filter

    def createFileFilter(self) -> str:  # noqa: N802 - Qt API
        return self.file_filter

    def clone(self) -> LayerChoice:
        copy = type(self)(self.name(), self.description(), self.dataTypes(), self.file_filter)
        copy.setFlags(self.flags())
        return copy


def is_surface_file(value: Any) -> bool:
    """Whether ``value`` names a DEM GeoTIFF or a LandXML TIN (a surface as the estimate's reference)."""
    return isinstance(value, str) and Path(value).suffix.lower().lstrip(".") in SURFACE_EXTENSIONS


class EpochsParameter(QgsProcessingParameterMultipleLayers):
    """The series' surveys: files (or layers) in time order, at least two; file paths written as
    they are (QGIS's own tries each as a vector and mesh layer to describe it, see
    :class:`CloudParameter`)."""

    def __init__(self, name: str, description: str) -> None:
        super().__init__(name, description, Qgis.ProcessingSourceType.File)
        self.setMinimumNumberInputs(2)

    def clone(self) -> EpochsParameter:
        copy = type(self)(self.name(), self.description())
        copy.setHelp(self.help())
        copy.setFlags(self.flags())
        copy.setMetadata(self.metadata())
        return copy

    def valueAsJsonObject(self, value: Any, context: QgsProcessingContext) -> Any:  # noqa: N802 - Qt API
        paths = file_values(value)
        return paths if paths is not None else super().valueAsJsonObject(value, context)

    def valueAsString(self, value: Any, context: QgsProcessingContext) -> tuple[str, bool]:  # noqa: N802 - Qt API
        paths = file_values(value)
        return (";".join(paths), True) if paths is not None else super().valueAsString(value, context)


def file_values(value: Any) -> list[str] | None:
    """``value`` as a list of file paths when every item names a point cloud file, else None."""
    items = [v for v in value.split(";") if v] if isinstance(value, str) else value
    if not isinstance(items, (list, tuple)) or not items:
        return None
    paths = [file_value(item) for item in items]
    return None if None in paths else paths
