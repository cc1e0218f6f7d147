"""Estimate soil volume change: the whole pipeline from two point clouds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    QgsProcessing,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingParameterFeatureSink,
    QgsProcessingParameterFile,
    QgsProcessingParameterRasterDestination,
    QgsProcessingParameterVectorDestination,
)

from . import engine, estimate_outputs, optionparams, params, styles
from .base import SoilVolumeAlgorithm
from .optiontable import reword_html

RASTERS = {  # parameter -> (engine output key, style, layer name, sort key: higher = on top)
    "DIFFERENCE": ("difference", styles.DIVERGING, "Difference", 40),
    "PLANE_OFFSET": ("plane_offset", styles.DIVERGING, "Vertical correction", 30),
    "DEM_AFTER": ("dem_after", styles.TERRAIN, "DEM after (registered)", 20),
    "DEM_BEFORE": ("dem_before", styles.TERRAIN, "DEM before", 10),
    "FILLED_MASK": ("filled_mask", styles.MASK, "Refilled cells", 45),  # over the difference, half see-through
    "GRADE": ("grade", styles.GRADE, "Grade: cut to go, on grade, fill to go", 42),
}
OPTIONAL_RASTERS = {"FILLED_MASK"}  # not written unless asked
WITH_TOLERANCE = {"GRADE"}  # written by the engine only with an on-grade tolerance (a design as BEFORE)
DESCRIPTIONS = {  # parameter labels
    "DIFFERENCE": "Difference (after − before, corrected)",
    "GRADE": "Grade classes (1 cut to go, 2 on grade, 3 fill to go; with an on-grade tolerance)",
    "FILLED_MASK": "Refilled cells (1 = interpolated from neighbours: a sparse cell or a hole)",
}
REPORT_ASSETS = (".png", ".svg", ".jpg", ".css", ".js")
CRS_HINT = "Set the 'Before CRS override' / 'After CRS override' parameters to the clouds' CRS."

HELP = """\
<p>Estimates the soil volume that changed between two georeferenced point clouds of the same
site (e.g. UAV photogrammetry or LiDAR surveys before and after earthworks).</p>
<h3>Method</h3>
<p>The before cloud is cropped to the after cloud's footprint plus the <b>crop radius</b>. The
after cloud is registered onto the before cloud (a coarse FPFH + RANSAC step kept only when it
beats the GPS georeferencing, then robust ICP with change areas down-weighted). Both clouds are
gridded on one shared grid (<b>cell size</b>; automatic from the point density when not set);
a remaining vertical bias is estimated on stable ground and removed (<b>vertical bias
correction</b>); cut, fill and net volumes are summed with their 95 % uncertainty.</p>
<h3>Inputs</h3>
<p>One <b>before</b> and one <b>after</b> point cloud: a point cloud layer or a file (LAS,
LAZ, COPC, VPC of tiles, PLY, PCD, XYZ/TXT/CSV). Give a CRS override when a file has no CRS
(PLY, XYZ); one that differs from the CRS in a file's header is refused. Optional <b>zones</b>
(polygons) get their own volumes; optional <b>stable ground</b>
polygons mark ground known not to have changed. Advanced parameters tune each step.</p>
<p><b>A surface as the reference</b>: the before input may be a single-band DEM raster layer or
GeoTIFF (a grading plan, or an earlier DEM; in its CRS, or the before CRS override when it has
none), or a LandXML TIN design file (.xml, .landxml: its first surface, or the one named by the
LandXML surface name; its units and CRS honoured). Nothing is registered against it (the survey
must be well georeferenced) and no bias is
corrected by default; the volumes are above (fill) and below (cut) the design over the survey's
footprint, and the verdict checks that the survey agrees with the design on unchanged ground.</p>
<h3>Outputs</h3>
<p>The areas of significant change as cut and fill polygons on top (outlined red and blue), each
with its area and volume (the headline cut and fill are their sums); under them the corrected
difference raster (red = cut, blue = fill), both DEMs and the vertical correction raster, styled,
and optionally the refilled cells (1 where a survey had too few points or a hole and the height was
interpolated from the neighbouring cells) and, against a design with an on-grade tolerance, the grade
classes (cut to go, on grade, fill to go),
in a group of each run named after the pair, its run number and time;
an HTML report; optionally the JSON report, the volumes as a table of one row (which a model
can return: its outputs are layers and files, not numbers), the per-zone volume table (as a layer
and as a CSV)
and the registered after cloud (off by default: it is the most expensive output). Numbers: net,
cut and fill volumes (m³) with their ± half-widths, the same over the detected change areas,
the level of detection (m), compared area, cell size, registration rotation (°) and shift (m);
strings: the quality verdict and messages, the significance in words and the 4×4
transform.</p>"""


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
    _clouds = {"BEFORE": "Before", "AFTER": "After"}

    def shortDescription(self) -> str:  # noqa: N802
        return self.tr("Cut, fill and net volume between two point cloud surveys of one site.")

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        self.addParameter(params.cloud_param("BEFORE", "Before", surface=True))
        self.addParameter(params.cloud_param("AFTER", "After"))
        for param in optionparams.parameters():
            self.addParameter(param)
        for key, label in (("BEFORE_PIPELINE", "before"), ("AFTER_PIPELINE", "after")):
            self.addParameter(
                params.advanced(
                    QgsProcessingParameterFile(
                        key, self.tr(f"PDAL pipeline for the {label} cloud (JSON)"), extension="json", optional=True
                    )
                )
            )
        self.add_destinations()
        estimate_outputs.add_outputs(self)

    def add_destinations(self) -> None:
        self.addParameter(QgsProcessingParameterRasterDestination("DIFFERENCE", self.tr(DESCRIPTIONS["DIFFERENCE"])))
        for key in ("DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET", "FILLED_MASK", "GRADE"):
            self.addParameter(
                QgsProcessingParameterRasterDestination(
                    key,
                    self.tr(DESCRIPTIONS.get(key, RASTERS[key][2])),
                    optional=True,
                    createByDefault=key not in OPTIONAL_RASTERS,
                )
            )
        self.addParameter(params.ReportDestination("REPORT", self.tr("HTML report"), "HTML files (*.html)", True))
        self.addParameter(params.optional_file("REPORT_JSON", self.tr("JSON report"), "JSON files (*.json)"))
        self.addParameter(
            QgsProcessingParameterFeatureSink(
                "ZONE_VOLUMES",
                self.tr("Volumes per zone"),
                QgsProcessing.TypeVectorPolygon,
                optional=True,
                createByDefault=True,
            )
        )
        self.addParameter(
            QgsProcessingParameterVectorDestination(
                "CHANGE_AREAS",
                self.tr("Areas of significant change (cut and fill polygons)"),
                QgsProcessing.TypeVectorPolygon,
                optional=True,
                createByDefault=True,
            )
        )
        self.addParameter(
            params.optional_file(
                "CONTOURS",
                self.tr("Contours (GeoPackage: layers difference, dem_before, dem_after; needs a contour interval)"),
                "GeoPackage (*.gpkg)",
            )
        )
        self.addParameter(
            params.optional_file(
                "SECTION_PROFILES",
                self.tr("Cross-sections (CSV; an SVG picture per line in the folder of its name; needs section lines)"),
                "CSV (*.csv)",
            )
        )
        self.addParameter(
            params.optional_file(
                "ZONES_CSV",
                self.tr("Volumes per zone (CSV: a row per zone, its interval's ends; needs zones)"),
                "CSV (*.csv)",
            )
        )
        self.addParameter(
            QgsProcessingParameterFeatureSink(
                "VOLUMES",
                self.tr("Volumes (a table of one row: net, cut, fill and their ±, the verdict)"),
                QgsProcessing.TypeVector,
                optional=True,
                createByDefault=False,
            )
        )
        self.addParameter(params.optional_file("REGISTERED", self.tr("Registered after cloud"), params.LAS_FILTER))

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        before = params.cloud_path(self, parameters, "BEFORE", context, "Before", surface=True)
        after = params.cloud_path(self, parameters, "AFTER", context, "After")
        registered = self.parameterAsFileOutput(parameters, "REGISTERED", context)
        options = optionparams.read_options(self, parameters, context, feedback)
        for key, given, needs in (
            (
                "CONTOURS",
                options.contour_interval > 0,
                "Contours: set the Contour interval (CONTOUR_INTERVAL) above 0.",
            ),
            ("SECTION_PROFILES", options.sections, "Cross-sections: give the Cross-section lines (SECTIONS)."),
            ("ZONES_CSV", options.zones, "Volumes per zone (CSV): give the Zones (ZONES)."),
        ):
            if self.parameterAsFileOutput(parameters, key, context) and not given:
                raise QgsProcessingException(needs)
        if options.tolerance is None and estimate_outputs.asked_for(parameters, "GRADE"):
            raise QgsProcessingException("Grade classes (GRADE): set the On-grade tolerance (TOLERANCE).")
        args = ["estimate", before, after] + engine.option_args(options, "estimate")
        for key, flag in (("BEFORE_PIPELINE", "--before-pipeline"), ("AFTER_PIPELINE", "--after-pipeline")):
            if self.parameterAsFile(parameters, key, context):
                args += [flag, self.parameterAsFile(parameters, key, context)]
        if registered:
            args.append("--registered-cloud")
        what = "point cloud"
        if params.is_surface_file(before):
            what = "surface (the reference: nothing is registered against it)"
        feedback.pushInfo(f"Before {what}: {before}\nAfter point cloud: {after}")
        with params.work_folder() as work:
            result = engine.run(
                [*args, "--out", str(work / "result")], feedback, skip=("quality (",), hint=CRS_HINT
            )  # the quality lines are logged with the results
            names = params.run_label(params.pair_label(before, after))
            return self.deliver(result, parameters, context, feedback, registered, names)

    def deliver(self, result, parameters, context, feedback, registered, names=(("", ""), "")) -> dict[str, Any]:
        """Copy the engine outputs to the destinations and collect the numeric outputs (``names``:
        :func:`params.run_label`'s, what the loaded layers and their group are called)."""
        outputs = {k: Path(v) for k, v in (result.get("outputs") or {}).items()}
        results = self.deliver_files(outputs, parameters, context, feedback, registered, names)
        report, summary = result.get("report") or {}, result.get("summary") or {}
        results.update(estimate_outputs.values(report, summary))
        results["ZONE_VOLUMES"] = estimate_outputs.write_zones(self, parameters, context, report)
        results["CHANGE_AREAS"] = estimate_outputs.write_change_areas(
            self, parameters, context, outputs.get("change_areas"), names
        )
        results["CONTOURS"] = estimate_outputs.write_contours(self, parameters, context, outputs.get("contours"), names)
        results["SECTION_PROFILES"] = estimate_outputs.write_sections(self, parameters, context, outputs)
        results["ZONES_CSV"] = estimate_outputs.write_zone_table(self, parameters, context, outputs)
        if results["NET_VOLUME"] is None:
            raise QgsProcessingException("The engine reported no volumes (no compared cells?).")
        results["VOLUMES"] = estimate_outputs.write_volumes(self, parameters, context, results)
        self.log_summary(results, feedback, estimate_outputs.good_news(report))
        return results

    def deliver_files(self, outputs, parameters, context, feedback, registered, names=(("", ""), "")) -> dict:
        results: dict[str, Any] = {}
        pair, group = names
        for key, (out_key, style, name, order) in RASTERS.items():
            if key in WITH_TOLERANCE and out_key not in outputs:  # no tolerance: nothing to load
                results[key] = None
                continue
            dest = params.output_layer(self, parameters, key, context)
            if dest and out_key not in outputs:
                raise QgsProcessingException(f"The engine wrote no {out_key} raster.")
            results[key] = params.deliver_raster(Path(outputs[out_key]), dest) if dest else None
            label = f"{name} ({pair[1] if key != 'DEM_BEFORE' else pair[0]})" if pair[1] else name
            styles.style_on_load(context, results[key], style, label, order, group)
        if registered and "after_registered" in outputs:
            results["REGISTERED"] = params.deliver_cloud(Path(outputs["after_registered"]), registered, feedback)
        for key, suffix in (("REPORT", ".html"), ("REPORT_JSON", ".json")):
            dest = self.parameterAsFileOutput(parameters, key, context)
            src = report_file(outputs, suffix)
            if dest and src is None:
                feedback.pushWarning(f"The engine wrote no {suffix} report.")
            elif dest:
                results[key] = self.copy_report(src, dest)
        self.report = results.get("REPORT")  # listed in the Results Viewer after the run
        return results

    @staticmethod
    def log_summary(results: dict[str, Any], feedback, good_news: int = 0) -> None:
        """The volumes in the log, and the quality messages as warnings (but a reliable run's, and
        the first ``good_news`` ones: the survey's agreement with a design, as information)."""

        def m3(key: str, sign: str = "") -> str:
            value = results.get(key)
            return "n/a" if value is None else f"{value + 0.0:{sign},.1f}"  # + 0.0: no "-0.0"

        feedback.pushInfo(
            f"Volumes (m³): net {m3('NET_VOLUME', '+')} ± {m3('NET_UNCERTAINTY')}, "
            f"cut {m3('CUT_VOLUME')} ± {m3('CUT_UNCERTAINTY')}, "
            f"fill {m3('FILL_VOLUME')} ± {m3('FILL_UNCERTAINTY')}"
        )
        feedback.pushInfo(results["SIGNIFICANCE"])
        if results["VERDICT"]:
            feedback.pushInfo(f"Quality: {results['VERDICT']}")
        reliable = results["VERDICT"] == "reliable"
        for k, line in enumerate(filter(None, results["QUALITY_MESSAGES"].split("\n"))):
            (feedback.pushInfo if reliable or k < good_news else feedback.pushWarning)(line)

    @staticmethod
    def copy_report(src: Path, dest: str) -> str:
        """Copy a report and any sibling files it links to (e.g. figures) next to it."""
        if src.suffix != ".html":
            return params.deliver_file(src, dest)
        params.dest_folder(Path(dest).parent)
        text = src.read_text(encoding="utf-8", errors="replace")
        page = reword_html(text)  # parameters, not flags
        params.write_atomically(dest, lambda partial: partial.write_text(page, encoding="utf-8"))
        for sibling in src.parent.iterdir():
            if sibling.suffix.lower() in REPORT_ASSETS and sibling.is_file() and f'"{sibling.name}"' in text:
                params.copy(sibling, str(Path(dest).parent / sibling.name))
        return dest
