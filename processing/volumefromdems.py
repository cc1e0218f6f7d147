"""Volume from the difference of two DEMs, in total and per polygon."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsFeature,
    QgsFeatureSink,
    QgsField,
    QgsFields,
    QgsProcessing,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputNumber,
    QgsProcessingParameterFeatureSink,
    QgsProcessingParameterFeatureSource,
    QgsProcessingParameterField,
    QgsProcessingParameterRasterDestination,
    QgsProcessingParameterRasterLayer,
    QgsRasterLayer,
    QgsWkbTypes,
)
from qgis.PyQt.QtCore import QMetaType

from . import engine, params, styles, widgets
from .base import SoilVolumeAlgorithm

HELP = """\
<p>Cut, fill and net volume between two DEMs you already have (e.g. from <i>Point cloud to
average-height DEM</i> or any survey), in total and per polygon.</p>
<p><b>No registration, no vertical bias correction and no uncertainty are applied</b>: the two
DEMs are subtracted as they are, so any offset between their georeferencing or vertical datums
is counted as volume (the log gives the median difference over the whole grid, where such an
offset shows). For two point clouds use <i>Estimate soil volume change</i>, which registers,
corrects on stable ground and gives the 95 % interval.</p>
<h3>Method</h3>
<p>Difference = after − before on the before DEM's grid (the after DEM is resampled onto it
when the grids differ). Fill sums the positive differences times the cell area, cut the
negative ones (as a positive number), net = fill − cut. Cells where either DEM is nodata are
not compared.</p>
<h3>Inputs</h3>
<p>Before and after DEMs (heights in metres, projected CRS); optionally a polygon layer of
zones (e.g. stockpiles, pits, lots) and a field naming them.</p>
<h3>Outputs</h3>
<p>The difference raster (diverging ramp centred on 0: red = cut, blue = fill), a table with
one row per zone (zone, name, cut, fill, net in m³ and compared area in m²; a single "total"
row when no zones are given) and the totals
NET_VOLUME, CUT_VOLUME, FILL_VOLUME and COMPARED_AREA over the whole compared area, and
MEDIAN_DIFFERENCE (m), the median of after − before over every compared cell.</p>"""

TABLE_FIELDS = (
    ("zone", QMetaType.Type.Int),
    ("name", QMetaType.Type.QString),
    ("cut", QMetaType.Type.Double),
    ("fill", QMetaType.Type.Double),
    ("net", QMetaType.Type.Double),
    ("area", QMetaType.Type.Double),
)


def table_fields() -> QgsFields:
    fields = QgsFields()
    for name, kind in TABLE_FIELDS:
        fields.append(QgsField(name, kind))
    return fields


def raster_file(layer: QgsRasterLayer | None, label: str) -> str:
    """The file behind a raster layer (the engine reads files with rasterio)."""
    if layer is None or not layer.isValid():
        raise QgsProcessingException(f"The {label} DEM is not a valid raster layer.")
    source = layer.source()
    if layer.providerType() != "gdal" or not Path(source.split("|")[0]).is_file():
        raise QgsProcessingException(
            f"The {label} DEM ({layer.name()}) is not a raster file; save it as a GeoTIFF first."
        )
    return source.split("|")[0]


class VolumeFromDems(SoilVolumeAlgorithm):
    """Cut/fill/net between two rasters, in total and per polygon."""

    _name = "volumefromdems"
    _display_name = "Volume from DEM difference"
    _help = HELP
    _tags = "volume,cut,fill,dem of difference,dod,stockpile,zonal,raster"
    _group = "Volume change"
    _group_id = "volume"

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        for key, label in (("BEFORE", "Before DEM"), ("AFTER", "After DEM")):  # no layer preselected
            self.addParameter(widgets.no_default_layer(QgsProcessingParameterRasterLayer(key, self.tr(label))))
        self.addParameter(
            QgsProcessingParameterFeatureSource(
                "ZONES", self.tr("Zones (polygons)"), [QgsProcessing.TypeVectorPolygon], optional=True
            )
        )
        self.addParameter(
            QgsProcessingParameterField(
                "ZONE_FIELD", self.tr("Zone name field"), parentLayerParameterName="ZONES", optional=True
            )
        )
        self.addParameter(QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Difference (after − before)")))
        self.addParameter(
            QgsProcessingParameterFeatureSink(
                "TABLE", self.tr("Volumes per zone"), QgsProcessing.TypeVector, optional=True, createByDefault=True
            )
        )
        for key, description in (
            ("NET_VOLUME", "Net volume change (m³, fill − cut)"),
            ("CUT_VOLUME", "Cut volume (m³)"),
            ("FILL_VOLUME", "Fill volume (m³)"),
            ("COMPARED_AREA", "Compared area (m²)"),
            ("MEDIAN_DIFFERENCE", "Median difference over the whole grid (m): a datum offset shows here"),
        ):
            self.addOutput(QgsProcessingOutputNumber(key, self.tr(description)))

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        before = raster_file(self.parameterAsRasterLayer(parameters, "BEFORE", context), "before")
        after = raster_file(self.parameterAsRasterLayer(parameters, "AFTER", context), "after")
        args = ["volume", before, after]
        if parameters.get("ZONES"):
            args += [
                "--zones",
                self.parameterAsCompatibleSourceLayerPath(
                    parameters, "ZONES", context, ["gpkg", "shp", "geojson"], "gpkg", feedback
                ),
            ]
            field = self.parameterAsString(parameters, "ZONE_FIELD", context)
            args += ["--zone-field", field] if field else []
        zones = "--zones" in args
        out = params.output_layer(self, parameters, "OUTPUT", context)
        with params.work_folder() as work:
            volumes = engine.run([*args, "--out", str(work / "difference.tif")], feedback)
            params.deliver_raster(work / "difference.tif", out)
        styles.style_on_load(context, out, styles.DIVERGING)
        total = volumes["total"]
        results: dict[str, Any] = {
            "OUTPUT": out,
            "NET_VOLUME": float(total["net"]),
            "CUT_VOLUME": float(total["cut"]),
            "FILL_VOLUME": float(total["fill"]),
            "COMPARED_AREA": float(total["area_m2"]),
            "MEDIAN_DIFFERENCE": volumes.get("median_difference_m"),
        }
        feedback.pushInfo(
            f"Volumes (m³): net {total['net']:.2f}, cut {total['cut']:.2f}, "
            f"fill {total['fill']:.2f} over {total['area_m2']:.1f} m²"
        )
        sink, table_id = (None, None)
        if not params.unset_output(parameters, "TABLE"):
            sink, table_id = self.parameterAsSink(
                parameters, "TABLE", context, table_fields(), QgsWkbTypes.NoGeometry, QgsCoordinateReferenceSystem()
            )
        if sink is not None:
            rows = (volumes.get("zones") or []) if zones else [{"id": 0, "name": "total", **total}]
            for zone in rows:
                feature = QgsFeature(table_fields())
                feature.setAttributes(
                    [
                        int(zone["id"]),
                        str(zone.get("name") or zone["id"]),
                        float(zone["cut"]),
                        float(zone["fill"]),
                        float(zone["net"]),
                        float(zone["area_m2"]),
                    ]
                )
                sink.addFeature(feature, QgsFeatureSink.FastInsert)
            results["TABLE"] = table_id
        return results
