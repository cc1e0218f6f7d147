"""The estimate's numbers and strings as Processing outputs, and the per-zone volume tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    QgsFeature,
    QgsFeatureSink,
    QgsField,
    QgsFields,
    QgsProcessing,
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsWkbTypes,
)
from qgis.PyQt.QtCore import QMetaType

from . import params, styles
from .optiontable import qgis_wording

# output -> (report section, key, description)
NUMBERS: dict[str, tuple[str, str, str]] = {
    "NET_VOLUME": ("volume_m3", "net", "Net volume change over the change areas (m³, fill − cut)"),
    "NET_UNCERTAINTY": ("uncertainty_m3", "net", "Net volume change: ± half-width (m³, 95 % by default)"),
    "CUT_VOLUME": ("volume_m3", "cut", "Cut volume over the areas of significant loss (m³)"),
    "CUT_UNCERTAINTY": ("uncertainty_m3", "cut", "Cut volume: ± half-width (m³)"),
    "FILL_VOLUME": ("volume_m3", "fill", "Fill volume over the areas of significant gain (m³)"),
    "FILL_UNCERTAINTY": ("uncertainty_m3", "fill", "Fill volume: ± half-width (m³)"),
    "UNCOMPENSATED_NET_VOLUME": (
        "volume_uncompensated_m3",
        "net",
        "Net volume change without the vertical correction (m³)",
    ),
    "ALL_CELLS_NET_VOLUME": (
        "volume_all_cells_m3",
        "net",
        "Net volume summed over every compared cell, as the paper does (m³)",
    ),
    "ALL_CELLS_NET_UNCERTAINTY": (
        "uncertainty_m3",
        "net_all_cells",
        "Net volume over every compared cell: ± half-width (m³)",
    ),
    "ALL_CELLS_CUT_VOLUME": ("volume_all_cells_m3", "cut", "Cut summed over every compared cell (m³, incl. noise)"),
    "ALL_CELLS_FILL_VOLUME": ("volume_all_cells_m3", "fill", "Fill summed over every compared cell (m³, incl. noise)"),
    "CHANGE_AREA": ("volume_m3", "area_m2", "Detected change area (m²)"),
    "LEVEL_OF_DETECTION": ("uncertainty_m3", "lod_m", "Level of detection (m)"),
    "COMPARED_AREA": ("grid", "compared_area_m2", "Compared area (m²)"),
    "CELL_SIZE": ("grid", "cell_m", "Cell size (m)"),
}
REGISTRATION = {  # output -> (summary.rotation_shift key, description)
    "ROTATION": ("rotation_deg", "Registration rotation (°)"),
    "SHIFT": ("shift_m", "Registration shift (m)"),
}
STRINGS = {
    "VERDICT": "Quality verdict (reliable, use with caution, not reliable)",
    "QUALITY_MESSAGES": "Quality messages (one per line)",
    "SIGNIFICANCE": "Significance of the net change, in words",
    "TRANSFORM": "Registration transform (4×4, JSON, after → before)",
}
ZONE_FIELDS = (
    ("zone_name", QMetaType.Type.QString),
    ("cut_m3", QMetaType.Type.Double),
    ("fill_m3", QMetaType.Type.Double),
    ("net_m3", QMetaType.Type.Double),
    ("net_pm_m3", QMetaType.Type.Double),
    ("area_m2", QMetaType.Type.Double),
)


def add_outputs(alg: QgsProcessingAlgorithm) -> None:
    for key, (_s, _k, text) in NUMBERS.items():
        alg.addOutput(QgsProcessingOutputNumber(key, alg.tr(text)))
    for key, (_k, text) in REGISTRATION.items():
        alg.addOutput(QgsProcessingOutputNumber(key, alg.tr(text)))
    for key, text in STRINGS.items():
        alg.addOutput(QgsProcessingOutputString(key, alg.tr(text)))


def values(report: dict[str, Any], summary: dict[str, Any]) -> dict[str, Any]:
    """Every number and string output, read defensively from report.json and the engine's
    summary of it (rotation and shift, verdict, significance)."""
    out: dict[str, Any] = {}
    for key, (section, field, _d) in NUMBERS.items():
        value = (report.get(section) or {}).get(field)
        out[key] = float(value) + 0.0 if isinstance(value, (int, float)) else None  # + 0.0: no -0.0
    for key, (field, _d) in REGISTRATION.items():
        out[key] = summary.get(field)
    quality = summary.get("quality") or {}
    out["VERDICT"] = str(quality.get("verdict") or "")
    out["QUALITY_MESSAGES"] = "\n".join(qgis_wording(m) for m in quality.get("messages") or [])
    out["SIGNIFICANCE"] = str(summary.get("significance") or "")
    out["TRANSFORM"] = params.to_json((report.get("registration") or {}).get("transform"))
    return out


def asked_for(parameters: dict[str, Any], key: str) -> bool:
    """Whether a layer output was given a file of its own (not left empty, not a temporary one)."""
    value = parameters.get(key)
    sink = getattr(value, "sink", None)
    text = sink.staticValue() if sink is not None else value
    return bool(text) and str(text) != QgsProcessing.TEMPORARY_OUTPUT


def good_news(report: dict[str, Any]) -> int:
    """How many of the quality messages, at their head, are good news: the survey's agreement with
    the design it is compared with (report.json's ``reference.agreement.agrees``)."""
    agreement = (report.get("reference") or {}).get("agreement") or {}
    return 1 if agreement.get("agrees") is True else 0


def zone_fields(source_fields: QgsFields) -> QgsFields:
    """The zones' own attributes and the volume fields (renamed when a zone field has the name)."""
    fields = QgsFields(source_fields)
    for name, kind in ZONE_FIELDS:
        fields.append(QgsField(name if fields.indexOf(name) < 0 else f"sv_{name}", kind))
    return fields


def write_zones(
    alg: QgsProcessingAlgorithm,
    parameters: dict[str, Any],
    context: QgsProcessingContext,
    report: dict[str, Any],
) -> str | None:
    """The ZONE_VOLUMES table: each zone polygon with cut, fill, net and the net's ± (report.json's)."""
    zones = report.get("zones") or []
    source = alg.parameterAsSource(parameters, "ZONES", context) if parameters.get("ZONES") else None
    if source is None or not zones or params.unset_output(parameters, "ZONE_VOLUMES"):
        return None
    fields = zone_fields(source.fields())
    sink, dest = alg.parameterAsSink(parameters, "ZONE_VOLUMES", context, fields, source.wkbType(), source.sourceCrs())
    if sink is None:
        return None
    features = [f for f in source.getFeatures() if f.hasGeometry()]
    if len(features) != len(zones):
        raise QgsProcessingException(
            f"The engine measured {len(zones)} zones but the ZONES layer has {len(features)} polygons."
        )
    for feature, zone in zip(features, zones, strict=True):
        pm = (zone.get("uncertainty_m3") or {}).get("net")  # the engine's interval (none from tiles yet)
        sink.addFeature(_zone_feature(feature, zone, fields, pm), QgsFeatureSink.FastInsert)
    return dest


VOLUME_FIELDS = (  # the VOLUMES table: field -> output
    ("net_m3", "NET_VOLUME"),
    ("net_pm_m3", "NET_UNCERTAINTY"),
    ("cut_m3", "CUT_VOLUME"),
    ("cut_pm_m3", "CUT_UNCERTAINTY"),
    ("fill_m3", "FILL_VOLUME"),
    ("fill_pm_m3", "FILL_UNCERTAINTY"),
    ("change_area_m2", "CHANGE_AREA"),
    ("verdict", "VERDICT"),
)


def write_volumes(alg, parameters: dict[str, Any], context: QgsProcessingContext, results: dict[str, Any]):
    """The VOLUMES table: one row of the run's numbers (a destination, so a model can make it one of
    its outputs: QGIS's models return destinations only, not numbers)."""
    if not parameters.get("VOLUMES") or params.unset_output(parameters, "VOLUMES"):
        return None
    fields = QgsFields()
    for name, key in VOLUME_FIELDS:
        fields.append(QgsField(name, QMetaType.Type.QString if key == "VERDICT" else QMetaType.Type.Double))
    sink, dest = alg.parameterAsSink(parameters, "VOLUMES", context, fields, QgsWkbTypes.Type.NoGeometry)
    if sink is None:
        return None
    row = QgsFeature(fields)
    row.setAttributes([results.get(key) for _name, key in VOLUME_FIELDS])
    sink.addFeature(row, QgsFeatureSink.FastInsert)
    return dest


def write_change_areas(alg, parameters: dict[str, Any], context: QgsProcessingContext, src, names) -> str | None:
    """The CHANGE_AREAS output: the engine's cut and fill polygons (GeoJSON) in the format the
    destination asks for (GDAL of QGIS), styled and named after the pair when loaded (``names``:
    :func:`params.run_label`'s), on top of the run's group."""
    dest = params.output_layer(alg, parameters, "CHANGE_AREAS", context)
    if not dest:
        return None
    if src is None or not Path(src).is_file():
        raise QgsProcessingException("The engine wrote no change-area polygons.")
    from osgeo import gdal

    params.dest_folder(Path(dest).parent)
    Path(dest).unlink(missing_ok=True)
    if gdal.VectorTranslate(dest, str(src)) is None:
        raise QgsProcessingException(f"Cannot write {dest} (unsupported vector format?).")
    (_before, after), group = names
    label = f"Areas of significant change ({after})" if after else "Areas of significant change"
    # sort key 50: over the difference (40, opaque), the correction and the DEMs
    styles.style_on_load(context, dest, styles.CHANGE_AREAS, label, 50, group)
    return dest


CONTOUR_LAYERS = (  # layer of contours.gpkg -> name when loaded (the run's pair after it)
    ("difference", "Contours of the difference"),
    ("dem_before", "Contours before"),
    ("dem_after", "Contours after"),
)


def write_contours(alg, parameters: dict[str, Any], context: QgsProcessingContext, src, names) -> str | None:
    """The CONTOURS output: the engine's contours.gpkg copied, and each of its line layers loaded
    (on top of the run's group) when Processing loads the outputs."""
    dest = alg.parameterAsFileOutput(parameters, "CONTOURS", context)
    if not dest:
        return None
    if src is None or not Path(src).is_file():
        raise QgsProcessingException("The engine wrote no contours (is the contour interval above 0?).")
    params.deliver_file(Path(src), dest)
    (before, after), group = names
    asked = getattr(parameters.get("CONTOURS"), "destinationProject", None) is not None
    if not (asked or context.willLoadLayerOnCompletion(dest)):
        return dest
    loads = context.layersToLoadOnCompletion()
    context.setLayersToLoadOnCompletion({k: v for k, v in loads.items() if k != dest})  # its layers instead
    for layer, label in CONTOUR_LAYERS:
        pair = before if layer == "dem_before" else after
        name = f"{label} ({pair})" if pair else label
        details = QgsProcessingContext.LayerDetails(name, context.project(), "CONTOURS")
        details.groupName, details.layerSortKey = group, 60
        context.addLayerToLoadOnCompletion(f"{dest}|layername={layer}", details)
    return dest


def write_sections(alg, parameters: dict[str, Any], context: QgsProcessingContext, outputs: dict) -> str | None:
    """The SECTION_PROFILES output: the engine's sections.csv copied, and its pictures into the
    folder named after it (``profiles.csv`` -> ``profiles/``)."""
    dest = alg.parameterAsFileOutput(parameters, "SECTION_PROFILES", context)
    if not dest:
        return None
    src = Path(outputs["sections"]).parent / "sections.csv" if outputs.get("sections") else None
    if src is None or not src.is_file():
        raise QgsProcessingException("The engine wrote no cross-sections (are the section lines given?).")
    params.deliver_file(src, dest)
    pictures = Path(dest).with_suffix("")
    for svg in sorted((src.parent / "sections").glob("*.svg")):
        params.dest_folder(pictures)
        params.copy(svg, str(pictures / svg.name))
    return dest


def write_zone_table(alg, parameters: dict[str, Any], context: QgsProcessingContext, outputs: dict) -> str | None:
    """The ZONES_CSV output: the engine's zones.csv (a row per zone: net, cut and fill with their
    interval's ends, areas) copied."""
    dest = alg.parameterAsFileOutput(parameters, "ZONES_CSV", context)
    if not dest:
        return None
    folder = Path(outputs["report_json"]).parent if outputs.get("report_json") else None
    if folder is None or not (folder / "zones.csv").is_file():
        raise QgsProcessingException("The engine wrote no zones.csv (do the zones overlap the surveys?).")
    return params.deliver_file(folder / "zones.csv", dest)


def _zone_feature(feature: QgsFeature, zone: dict[str, Any], fields: QgsFields, pm) -> QgsFeature:
    out = QgsFeature(fields)
    out.setGeometry(feature.geometry())
    extra = [zone.get("name"), zone.get("cut"), zone.get("fill"), zone.get("net"), pm, zone.get("area_m2")]
    out.setAttributes(list(feature.attributes()) + extra)
    return out
