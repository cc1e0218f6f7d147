"""Stockpile volumes of one survey (``soilvolume stockpile``), in toe polygons or found."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    QgsProcessing,
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingOutputFile,
    QgsProcessingOutputNumber,
    QgsProcessingParameterFeatureSource,
    QgsProcessingParameterField,
    QgsProcessingParameterFolderDestination,
)

from . import engine, optionparams, params
from .base import SoilVolumeAlgorithm

HELP = """\
<p>The volume of each stockpile of one survey above its base, with a 95 % interval that holds
the point noise and how much the base choice moves it, its area, height and, with a density,
its tonnes.</p>
<h3>Inputs</h3>
<p>A point cloud file; optionally a polygon layer of the piles' toe outlines (the polygon is the
mask), its <b>name</b> field and its <b>density</b> field (t/m³). Without polygons the piles are
found as regions rising above the surrounding ground and their outlines written. The
<b>base</b>: triangulated (through the toe line), plane, lowest, average, highest,
elevation:Z or surface:DEM (a GeoTIFF such as an earlier survey's DEM).</p>
<h3>Outputs</h3>
<p>A folder with report.json, piles.gpkg (the polygons with the volumes), piles.csv and
report.html (the table and each pile's warnings, e.g. a toe running over a slope).</p>"""

OUTPUTS = ("report.json", "report.html", "piles.csv", "piles.gpkg")


class StockpileVolumes(SoilVolumeAlgorithm):
    """One survey's stockpile inventory, the engine run out of process."""

    _name = "stockpilevolumes"
    _display_name = "Stockpile volumes"
    _help = HELP
    _tags = "stockpile,inventory,volume,tonnage,toe,base,pile"
    _group = "Volume change"
    _group_id = "volume"
    _clouds = {"INPUT": "Survey"}

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        self.addParameter(params.cloud_param("INPUT", "Survey"))
        self.addParameter(params.crs_param("CRS", "Survey"))
        self.addParameter(
            QgsProcessingParameterFeatureSource(
                "PILES", self.tr("Pile toe polygons"), [QgsProcessing.TypeVectorPolygon], optional=True
            )
        )
        self.addParameter(
            QgsProcessingParameterField("NAME_FIELD", self.tr("Pile name field"), None, "PILES", optional=True)
        )
        numeric = QgsProcessingParameterField.Numeric
        self.addParameter(
            QgsProcessingParameterField(
                "DENSITY_FIELD", self.tr("Bulk density field (t/m³)"), None, "PILES", numeric, optional=True
            )
        )
        for param in optionparams.parameters("stockpile"):
            self.addParameter(param)
        self.addParameter(QgsProcessingParameterFolderDestination("OUTPUT_FOLDER", self.tr("Output folder")))
        self.addOutput(QgsProcessingOutputFile("REPORT", self.tr("HTML report")))
        self.addOutput(QgsProcessingOutputNumber("PILES_COUNT", self.tr("Piles")))
        self.addOutput(QgsProcessingOutputNumber("TOTAL_VOLUME", self.tr("Total volume (m³)")))

    def pile_args(self, parameters: dict[str, Any], context: QgsProcessingContext, feedback) -> list[str]:
        """``--piles FILE`` (the layer as a file the engine reads) and its fields, or nothing."""
        if not parameters.get("PILES"):
            return []
        path = self.parameterAsCompatibleSourceLayerPath(
            parameters, "PILES", context, ["gpkg", "shp", "geojson"], "gpkg", feedback
        )
        args = ["--piles", path]
        for key, flag in (("NAME_FIELD", "--name-field"), ("DENSITY_FIELD", "--density-field")):
            field = self.parameterAsString(parameters, key, context)
            args += [flag, field] if field else []
        return args

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        cloud = params.cloud_path(self, parameters, "INPUT", context, "Survey")
        crs = params.crs_text(self, parameters, "CRS", context)
        options = optionparams.read_options(self, parameters, context, feedback, "stockpile")
        dest = Path(self.parameterAsString(parameters, "OUTPUT_FOLDER", context))
        args = ["stockpile", cloud, *self.pile_args(parameters, context, feedback)]
        args += [*engine.option_args(options, "stockpile"), *(["--crs", crs] if crs else [])]
        with params.work_folder() as work:
            result = engine.run([*args, "--out", str(work / "out")], feedback)
            params.dest_folder(dest)
            for name in OUTPUTS:
                if (work / "out" / name).is_file():
                    params.copy(work / "out" / name, str(dest / name))
        self.report = str(dest / "report.html")
        feedback.pushInfo(f"{result['piles']} piles, {result['volume_m3']:,.1f} m³ in all")
        return {
            "OUTPUT_FOLDER": str(dest),
            "REPORT": self.report,
            "PILES_COUNT": int(result["piles"]),
            "TOTAL_VOLUME": float(result["volume_m3"]),
        }
