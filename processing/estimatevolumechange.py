"""Estimate soil volume change: the whole pipeline from two point clouds."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

from qgis.core import (
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterFile,
    QgsProcessingParameterFileDestination,
    QgsProcessingParameterNumber,
    QgsProcessingParameterRasterDestination,
    QgsProcessingUtils,
)

from . import engine, params, styles
from .base import SoilVolumeAlgorithm

RASTERS = {  # parameter -> (engine output key, style, layer name)
    "DIFFERENCE": ("difference", styles.DIVERGING, "Difference (after − before, corrected)"),
    "DEM_BEFORE": ("dem_before", styles.TERRAIN, "DEM before"),
    "DEM_AFTER": ("dem_after", styles.TERRAIN, "DEM after (registered)"),
    "PLANE_OFFSET": ("plane_offset", styles.DIVERGING, "Plane offset correction"),
}
NUMBERS = {  # output -> (report section, key, description)
    "NET_VOLUME": ("volume_m3", "net", "Net volume change (m³, fill − cut)"),
    "CUT_VOLUME": ("volume_m3", "cut", "Cut volume (m³)"),
    "FILL_VOLUME": ("volume_m3", "fill", "Fill volume (m³)"),
    "UNCOMPENSATED_NET_VOLUME": (
        "volume_uncompensated_m3", "net", "Net volume change without plane-offset correction (m³)"
    ),
    "COMPARED_AREA": ("grid", "compared_area_m2", "Compared area (m²)"),
    "CELL_SIZE": ("grid", "cell_m", "Cell size (m)"),
}
REPORT_ASSETS = (".png", ".svg", ".jpg", ".css", ".js")
CRS_HINT = "Set the 'Before CRS override' / 'After CRS override' parameters to the clouds' CRS."

HELP = """\
<p>Estimates the soil volume that changed between two georeferenced point clouds of the same
site (e.g. UAV photogrammetry or LiDAR surveys before and after earthworks).</p>
<h3>Method</h3>
<ol>
<li>The before cloud is cropped to the after cloud's footprint plus the <b>crop
radius</b>.</li>
<li>The after cloud is registered onto the before cloud: a coarse FPFH + RANSAC step (kept
only when it beats the GPS georeferencing) and a <b>fine registration</b> (robust ICP by
default; change areas are down-weighted).</li>
<li>Both clouds are gridded on one shared grid as average-height DEMs (<b>cell size</b>, 0 =
chosen from the point density).</li>
<li>A remaining vertical bias between the surveys is estimated on stable ground and removed
(<b>plane-offset correction</b>; choose <i>None</i> to switch compensation off).</li>
<li>Difference = after − before; cut, fill and net volumes are summed over the compared
cells.</li>
</ol>
<h3>Inputs</h3>
<p>Before/after clouds as files (LAS, LAZ, COPC, VPC of tiles, PLY, PCD, XYZ/TXT/CSV) or point cloud layers. Give
a CRS override when a file has no CRS (PLY, XYZ) or a wrong one. Optional PDAL pipelines
(JSON) pre-process each cloud when PDAL is available.</p>
<h3>Outputs</h3>
<p>The corrected difference raster (loaded with a diverging ramp centred on 0: red = cut, blue
= fill), both DEMs, the plane-offset raster, the registered after cloud (LAZ), an HTML report
and the numbers NET_VOLUME, CUT_VOLUME, FILL_VOLUME (m³) and UNCOMPENSATED_NET_VOLUME (without
the correction), plus the 4×4 registration transform (JSON).</p>"""


def report_file(outputs: dict[str, Any], suffix: str) -> Path | None:
    """The engine's report with this suffix (``report_html``/``report_json`` or any such file)."""
    preferred = outputs.get("report" + suffix.replace(".", "_"))
    if preferred is not None and Path(preferred).suffix == suffix:
        return Path(preferred)
    for path in outputs.values():
        if Path(path).suffix == suffix and Path(path).stem.startswith("report"):
            return Path(path)
    return None


class EstimateVolumeChange(SoilVolumeAlgorithm):
    """Whole pipeline: two clouds in, DEMs, difference and volumes out."""

    _name = "estimatevolumechange"
    _display_name = "Estimate soil volume change"
    _help = HELP
    _tags = "volume,cut,fill,earthworks,DEM of difference,DoD,point cloud,lidar,uav,registration,icp"
    _group = "Volume change"
    _group_id = "volume"

    def shortDescription(self) -> str:  # noqa: N802
        return self.tr("Cut, fill and net volume between two point cloud surveys of one site.")

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        for p in params.cloud_params("BEFORE", "Before") + params.cloud_params("AFTER", "After"):
            self.addParameter(p)
        self.addParameter(params.crs_param("BEFORE_CRS", "Before"))
        self.addParameter(params.crs_param("AFTER_CRS", "After"))
        self.addParameter(QgsProcessingParameterNumber(
            "CELL", self.tr("Cell size (m, 0 = automatic from point density)"),
            type=QgsProcessingParameterNumber.Double, defaultValue=0.0, minValue=0.0,
        ))
        self.addParameter(params.number_param(
            "RADIUS", self.tr("Crop radius around the after cloud (m)"), 30.0))
        self.addParameter(params.enum_param(
            "FINE", self.tr("Fine registration"), params.FINE_LABELS))
        self.addParameter(params.enum_param(
            "CORRECTION", self.tr("Plane-offset (vertical bias) correction"),
            params.CORRECTION_LABELS))
        for p in (
            params.enum_param("COARSE", self.tr("Coarse registration"), params.COARSE_LABELS),
            params.enum_param(
                "STATISTIC", self.tr("Cell height statistic"), params.STATISTIC_LABELS),
            params.enum_param("GROUND", self.tr("Ground points"), params.GROUND_LABELS),
            params.number_param(
                "FILL_HOLES", self.tr("Fill enclosed holes up to this area (m², 0 = off)"),
                engine.engine("options").Options().fill_holes),
            QgsProcessingParameterNumber(
                "SEED", self.tr("Random seed"), defaultValue=0, minValue=0),
            QgsProcessingParameterFile(
                "BEFORE_PIPELINE", self.tr("PDAL pipeline for the before cloud (JSON)"),
                extension="json", optional=True),
            QgsProcessingParameterFile(
                "AFTER_PIPELINE", self.tr("PDAL pipeline for the after cloud (JSON)"),
                extension="json", optional=True),
        ):
            self.addParameter(params.advanced(p))
        self.addParameter(QgsProcessingParameterRasterDestination(
            "DIFFERENCE", self.tr("Difference (after − before, corrected)")))
        self.addParameter(QgsProcessingParameterRasterDestination(
            "DEM_BEFORE", self.tr("DEM before"), optional=True, createByDefault=True))
        self.addParameter(QgsProcessingParameterRasterDestination(
            "DEM_AFTER", self.tr("DEM after (registered)"), optional=True, createByDefault=True))
        self.addParameter(QgsProcessingParameterRasterDestination(
            "PLANE_OFFSET", self.tr("Plane-offset correction raster"), optional=True,
            createByDefault=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            "REGISTERED", self.tr("Registered after cloud"), fileFilter=params.LAS_FILTER,
            optional=True, createByDefault=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            "REPORT", self.tr("HTML report"), fileFilter="HTML files (*.html)", optional=True,
            createByDefault=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            "REPORT_JSON", self.tr("JSON report"), fileFilter="JSON files (*.json)", optional=True,
            createByDefault=False))
        for key, (_s, _k, description) in NUMBERS.items():
            self.addOutput(QgsProcessingOutputNumber(key, self.tr(description)))
        self.addOutput(QgsProcessingOutputString(
            "TRANSFORM", self.tr("Registration transform (4×4, JSON, after → before)")))

    def checkParameterValues(  # noqa: N802
        self, parameters: dict[str, Any], context: QgsProcessingContext
    ) -> tuple[bool, str]:
        ok, message = params.check_clouds(parameters, {"BEFORE": "before", "AFTER": "after"})
        if not ok:
            return ok, message
        return super().checkParameterValues(parameters, context)

    def options(self, parameters: dict[str, Any], context: QgsProcessingContext):
        """The engine Options for these parameters."""
        enum = self.parameterAsEnum
        return engine.engine("options").Options().with_(
            before_crs=params.crs_text(self, parameters, "BEFORE_CRS", context),
            after_crs=params.crs_text(self, parameters, "AFTER_CRS", context),
            cell=params.optional_cell(self.parameterAsDouble(parameters, "CELL", context)),
            radius=self.parameterAsDouble(parameters, "RADIUS", context),
            fine=params.FINE_METHODS[enum(parameters, "FINE", context)],
            correction=params.CORRECTIONS[enum(parameters, "CORRECTION", context)],
            coarse=params.COARSE_METHODS[enum(parameters, "COARSE", context)],
            statistic=params.STATISTICS[enum(parameters, "STATISTIC", context)],
            ground=params.GROUNDS[enum(parameters, "GROUND", context)],
            fill_holes=self.parameterAsDouble(parameters, "FILL_HOLES", context),
            seed=self.parameterAsInt(parameters, "SEED", context),
        )

    def processAlgorithm(  # noqa: N802
        self, parameters: dict[str, Any], context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        engine.require(engine.POINT_CLOUD_DEPS)
        before = params.cloud_path(self, parameters, "BEFORE", context, "Before")
        after = params.cloud_path(self, parameters, "AFTER", context, "After")
        pipelines = {
            key: (self.parameterAsFile(parameters, key, context) or None)
            for key in ("BEFORE_PIPELINE", "AFTER_PIPELINE")
        }
        options = self.options(parameters, context)
        registered = self.parameterAsFileOutput(parameters, "REGISTERED", context)
        options = options.with_(keep_registered_cloud=bool(registered))
        feedback.pushInfo(f"Before: {before}\nAfter: {after}")
        work = Path(tempfile.mkdtemp(prefix="soilvolume_", dir=QgsProcessingUtils.tempFolder()))
        try:
            with engine.engine_errors(feedback, CRS_HINT):
                result = engine.engine("api").estimate(
                    before, after, work, options, overwrite=True, hooks=engine.hooks(feedback),
                    before_pipeline=pipelines["BEFORE_PIPELINE"],
                    after_pipeline=pipelines["AFTER_PIPELINE"],
                )
            return self.deliver(result, parameters, context, feedback, registered)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def deliver(self, result, parameters, context, feedback, registered) -> dict[str, Any]:
        """Copy the engine outputs to the destinations and collect the numeric outputs."""
        outputs = result.outputs
        results: dict[str, Any] = {}
        for key, (out_key, style, name) in RASTERS.items():
            dest = self.parameterAsOutputLayer(parameters, key, context)
            if dest and out_key not in outputs:
                raise QgsProcessingException(f"The engine wrote no {out_key} raster.")
            results[key] = params.deliver_raster(Path(outputs[out_key]), dest) if dest else None
            styles.style_on_load(context, results[key], style, name)
        if registered and "after_registered" in outputs:
            results["REGISTERED"] = params.deliver_cloud(
                Path(outputs["after_registered"]), registered)
        for key, suffix in (("REPORT", ".html"), ("REPORT_JSON", ".json")):
            dest = self.parameterAsFileOutput(parameters, key, context)
            src = report_file(outputs, suffix)
            if dest and src is None:
                feedback.pushWarning(f"The engine wrote no {suffix} report.")
            elif dest:
                results[key] = self.copy_report(src, dest)
        report = result.report
        for key, (section, field, _d) in NUMBERS.items():
            value = report.get(section, {}).get(field)
            results[key] = float(value) if value is not None else None
        results["TRANSFORM"] = params.to_json(report.get("registration", {}).get("transform"))
        if results["NET_VOLUME"] is None:
            raise QgsProcessingException("The engine reported no volumes (no compared cells?).")
        feedback.pushInfo(
            "Volumes (m³): net {NET_VOLUME:.2f}, cut {CUT_VOLUME:.2f}, fill {FILL_VOLUME:.2f}; "
            "without correction: net {UNCOMPENSATED_NET_VOLUME}".format(**results)
        )
        return results

    @staticmethod
    def copy_report(src: Path, dest: str) -> str:
        """Copy a report and any sibling files it links to (e.g. figures) next to it."""
        params.deliver_file(src, dest)
        if src.suffix == ".html":
            text = src.read_text(encoding="utf-8", errors="replace")
            for sibling in src.parent.iterdir():
                if (sibling.suffix.lower() in REPORT_ASSETS and sibling.is_file()
                        and f'"{sibling.name}"' in text):
                    shutil.copyfile(sibling, Path(dest).parent / sibling.name)
        return dest
