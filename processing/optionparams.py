"""Processing parameters built from the engine's option table (``soilvolume.options.Options``),
for the fields each engine command takes (declared next to each option).

One parameter per option field: name = field name upper-cased, description = its label, help = its
help text, choices -> a string-valued enum, lengths in metres -> a distance widget, numbers with
the table's range. Options added to the table later appear here without any change.
"""

from __future__ import annotations

from dataclasses import MISSING, Field
from typing import Any

from qgis.core import (
    Qgis,
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingParameterBoolean,
    QgsProcessingParameterCrs,
    QgsProcessingParameterDefinition,
    QgsProcessingParameterDistance,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFeatureSource,
    QgsProcessingParameterFile,
    QgsProcessingParameterNumber,
    QgsProcessingParameterString,
)

from .inputs import LANDXML_FILTER, SURFACE_FILTER
from .optiontable import description, key, option_fields, options_class, qgis_wording, value_kind
from .params import crs_text

CRS_FIELDS = {"before_crs", "after_crs"}
POLYGON_FIELDS = {"stable_mask", "zones"}
LINE_FIELDS = {"sections"}  # a layer of lines
SURFACE_FIELDS = {"design"}  # a series' design: a GeoTIFF or a LandXML file
BASIC = (
    "before_crs",
    "after_crs",
    "cell",
    "radius",
    "georeferencing",
    "fine",
    "correction",
    "zones",
    "stable_mask",
)  # shown first, in this order; the rest is advanced, in table order
POLYGON_FORMATS = ["gpkg", "shp", "geojson"]


def parameter(field: Field) -> QgsProcessingParameterDefinition:
    """The Processing parameter of one option field."""
    param = _make(field)
    param.setHelp(qgis_wording(field.metadata.get("help") or ""))  # no command-line flags
    if field.name not in BASIC:
        param.setFlags(param.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
    return param


def parameters(command: str = "estimate") -> list[QgsProcessingParameterDefinition]:
    table = option_fields(command)
    first = sorted((f for f in table if f.name in BASIC), key=lambda f: BASIC.index(f.name))
    return [parameter(f) for f in first + [f for f in table if f.name not in BASIC]]


def _make(field: Field) -> QgsProcessingParameterDefinition:
    meta, name, label = field.metadata, key(field), description(field)
    default = None if field.default is MISSING else field.default
    optional = default is None
    if field.name in CRS_FIELDS:
        return QgsProcessingParameterCrs(name, label, optional=True)
    if field.name in POLYGON_FIELDS | LINE_FIELDS:
        types = Qgis.ProcessingSourceType
        kind = types.VectorLine if field.name in LINE_FIELDS else types.VectorPolygon
        return QgsProcessingParameterFeatureSource(name, label, [kind], optional=True)
    if field.name in SURFACE_FIELDS:
        return QgsProcessingParameterFile(name, label, fileFilter=f"{SURFACE_FILTER};;{LANDXML_FILTER}", optional=True)
    if meta.get("choices"):
        return QgsProcessingParameterEnum(
            name, label, options=list(meta["choices"]), defaultValue=default, usesStaticStrings=True
        )
    kind = value_kind(field)
    if kind == "bool":
        return QgsProcessingParameterBoolean(name, label, defaultValue=bool(default))
    if kind in ("float", "int"):
        return _number(field, name, label, default, optional)
    return QgsProcessingParameterString(name, label, defaultValue=default, optional=optional)


def _number(field: Field, name: str, label: str, default: Any, optional: bool):
    meta = field.metadata
    if meta.get("unit") == "m" and value_kind(field) == "float":
        param = QgsProcessingParameterDistance(name, label, defaultValue=default, optional=optional)
        param.setDefaultUnit(Qgis.DistanceUnit.Meters)
    else:
        kind = (
            QgsProcessingParameterNumber.Integer if value_kind(field) == "int" else QgsProcessingParameterNumber.Double
        )
        param = QgsProcessingParameterNumber(name, label, type=kind, defaultValue=default, optional=optional)
    param.setMetadata({"widget_wrapper": {"decimals": decimals(default, meta.get("lo"))}})
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is not None:
        param.setMinimum(0.0 if optional else lo)  # optional numbers: 0 also means automatic
    if hi is not None:
        param.setMaximum(hi)
    return param


def decimals(*values: float | None) -> int:
    """Decimals the widget shows: enough for the default and the lower bound (1 to 4), so a
    radius reads 30.0, not 30.000000."""
    need = 1
    for value in values:
        if isinstance(value, float):
            need = max(need, next((d for d in range(1, 5) if abs(round(value, d) - value) < 1e-9), 4))
    return need


def read_options(
    alg: QgsProcessingAlgorithm,
    parameters: dict[str, Any],
    context: QgsProcessingContext,
    feedback: QgsProcessingFeedback | None = None,
    command: str = "estimate",
):
    """The engine's Options from the parameters of the fields ``command`` takes."""
    given = {}
    for field in option_fields(command):
        if alg.parameterDefinition(key(field)) is None:
            continue
        value = _value(alg, field, parameters, context, feedback)
        if value is not None or field.default is None:
            given[field.name] = value
    return options_class()(**given)  # ranges are checked by the engine, which names the field


def _value(alg, field: Field, parameters: dict[str, Any], context, feedback) -> Any:
    name = key(field)
    if field.name in CRS_FIELDS:
        return crs_text(alg, parameters, name, context)
    if field.name in POLYGON_FIELDS | LINE_FIELDS:
        if not parameters.get(name):
            return None
        return (
            alg.parameterAsCompatibleSourceLayerPath(parameters, name, context, POLYGON_FORMATS, "gpkg", feedback)
            or None
        )
    if field.metadata.get("choices"):
        return alg.parameterAsEnumString(parameters, name, context) or None
    return _scalar(alg, field, parameters, name, context)


def _scalar(alg, field: Field, parameters: dict[str, Any], name: str, context) -> Any:
    kind = value_kind(field)
    if kind == "bool":
        return alg.parameterAsBool(parameters, name, context)
    if kind not in ("float", "int"):
        return alg.parameterAsString(parameters, name, context) or None
    raw = parameters.get(name, alg.parameterDefinition(name).defaultValue())
    if raw is None or raw == "":
        return None
    value = (
        alg.parameterAsInt(parameters, name, context)
        if kind == "int"
        else alg.parameterAsDouble(parameters, name, context)
    )
    if field.default is None and value <= 0:
        return None  # optional numbers (e.g. the cell size): 0 = automatic
    return value
