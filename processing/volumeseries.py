"""Volume change over a series of surveys: ``soilvolume series`` run as the engine subprocess."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from qgis.core import (
    QgsMapLayer,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterString,
    QgsProperty,
)

from . import engine, inputs, optionparams, params, widgets
from .base import SoilVolumeAlgorithm

HELP = """\
<p>The soil volume moved between each pair of consecutive surveys of one site, and from the
first survey to the last, with their 95 % uncertainty.</p>
<h3>Method</h3>
<p>The first point cloud (E0) is the reference. Every later survey is registered into E0's
frame on ground that stayed stable between the two, all surveys are gridded on one grid, and
each later survey is corrected once, relative to E0, for a remaining vertical bias on stable
ground. A period's change is the difference of two corrected surveys, so the periods' net
volumes add up to the cumulative net exactly; a survey's error is shared by the two periods
around it, and the cumulative's comes from the first and the last surveys only.</p>
<h3>Inputs</h3>
<p>The <b>point clouds in time order</b>, the reference first (LAS, LAZ, COPC, VPC, PLY, PCD,
XYZ/TXT/CSV files, or point cloud layers). Optional <b>survey dates</b> (YYYY-MM-DD, one per
cloud, comma-separated; an empty entry keeps the date of the file: a LAS header's creation
day). The 'Before CRS override' applies to the first cloud, the 'After CRS override' to the
others. Advanced parameters tune each step as in "Estimate soil volume change". With a <b>Design
surface</b> (a DEM GeoTIFF or a LandXML TIN) and an <b>On-grade tolerance</b>, each survey is graded
against the design (its share on grade, the cut and fill still to go, per zone with Zones) and each
period's progress is the cut and fill to go it did.</p>
<h3>Outputs</h3>
<p>A folder with each survey's DEM, each period's difference and the cumulative difference
(GeoTIFFs), the ledger (CSV: one row per period and the cumulative, with dates, net, cut, fill
and their ±), report.json and an HTML report with the cumulative cut and fill over time. The
ledger and the report can also be saved elsewhere. Numbers: the cumulative net, cut and fill
(m³) with their ±; the periods as a JSON string, each with its quality verdict (reliable, use
with caution, not reliable) and the reasons.</p>"""

NUMBERS = {  # output -> (report key path, label)
    "CUMULATIVE_NET": (("volume_m3", "net"), "Cumulative net volume (m³)"),
    "CUMULATIVE_CUT": (("volume_m3", "cut"), "Cumulative cut volume (m³)"),
    "CUMULATIVE_FILL": (("volume_m3", "fill"), "Cumulative fill volume (m³)"),
    "CUMULATIVE_NET_UNCERTAINTY": (("uncertainty_m3", "net"), "Cumulative net volume ± (m³, 95 %)"),
}


def epoch_paths(alg, parameters: dict[str, Any], context: QgsProcessingContext) -> list[str]:
    """The clouds in the order given: file paths, or the point cloud layers' source files (a
    single string may list files separated by ';')."""
    value = parameters.get("EPOCHS")
    if isinstance(value, QgsProperty):
        value = value.valueAsString(context.expressionContext())[0]  # (text, ok)
    if isinstance(value, str):
        value = [v for v in value.split(";") if v.strip()]
    out = []
    for item in value or []:
        if isinstance(item, QgsMapLayer):
            out.append(item.source())
        elif isinstance(item, str) and not Path(item).suffix:  # a layer id or name of the project
            layer = context.getMapLayer(item) or (context.project() and context.project().mapLayer(item))
            out.append(layer.source() if layer is not None else item)
        else:
            out.append(str(item))
    if len(out) < 2:
        raise QgsProcessingException(
            f"A series needs at least two surveys ({len(out)} given in 'Point clouds in time order'): "
            "the reference survey first, then one or more later ones."
        )
    for k, path in enumerate(out):
        params.check_cloud_file(path, f"Survey {k}")
    return out


class VolumeSeries(SoilVolumeAlgorithm):
    """A series of surveys: periods, cumulative, ledger."""

    _name = "volumeseries"
    _display_name = "Volume change over a series of surveys"
    _help = HELP
    _tags = "volume,cut,fill,earthworks,series,time series,monitoring,ledger,point cloud,lidar,uav"
    _group = "Volume change"
    _group_id = "volume"

    def shortDescription(self) -> str:  # noqa: N802
        return self.tr("Cut, fill and net volume per period over surveys of one site, and their sum.")

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        epochs = inputs.EpochsParameter("EPOCHS", self.tr("Point clouds in time order (the reference survey first)"))
        self.addParameter(widgets.file_list(epochs, inputs.CLOUD_FILTER))  # keeps the paths it is given
        self.addParameter(
            QgsProcessingParameterString(
                "DATES", self.tr("Survey dates (YYYY-MM-DD, comma-separated; empty: from the files)"), optional=True
            )
        )
        for param in optionparams.parameters("series"):
            self.addParameter(param)
        self.addParameter(QgsProcessingParameterFolderDestination("OUTPUT_FOLDER", self.tr("Output folder")))
        self.addParameter(params.optional_file("LEDGER", self.tr("Ledger"), "CSV files (*.csv)"))
        self.addParameter(params.ReportDestination("REPORT", self.tr("HTML report"), "HTML files (*.html)", False))
        for key, (_, label) in NUMBERS.items():
            self.addOutput(QgsProcessingOutputNumber(key, self.tr(label)))
        self.addOutput(QgsProcessingOutputString("PERIODS", self.tr("Periods (JSON)")))

    def checkParameterValues(  # noqa: N802 - Qt API
        self, parameters: dict[str, Any], context: QgsProcessingContext
    ) -> tuple[bool, str]:
        """The surveys named (fewer than two, a missing or unsupported file) before QGIS's own
        check, whose "Incorrect parameter value" says neither which nor why."""
        try:
            epoch_paths(self, parameters, context)
        except QgsProcessingException as exc:
            return False, str(exc)
        return super().checkParameterValues(parameters, context)

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        paths = epoch_paths(self, parameters, context)
        options = optionparams.read_options(self, parameters, context, feedback, "series")
        args = ["series", *paths, *engine.option_args(options, "series")]
        dates = self.parameterAsString(parameters, "DATES", context)
        if dates.strip():
            args += ["--dates", dates]
        feedback.pushInfo("Surveys in time order:\n" + "\n".join(f"  E{k}: {p}" for k, p in enumerate(paths)))
        folder = Path(self.parameterAsString(parameters, "OUTPUT_FOLDER", context))
        with params.work_folder() as work:
            result = engine.run([*args, "--out", str(work / "result")], feedback)
            outputs = {k: Path(v) for k, v in (result.get("outputs") or {}).items()}
            return self.deliver(result.get("report") or {}, outputs, folder, parameters, context, feedback)

    def deliver(self, report, outputs, folder: Path, parameters, context, feedback) -> dict[str, Any]:
        """Every output copied whole into the folder (and the ledger and report where asked)."""
        params.dest_folder(folder)
        for src in outputs.values():
            params.copy(src, str(folder / src.name))
        results: dict[str, Any] = {"OUTPUT_FOLDER": str(folder)}
        for key, name in (("LEDGER", "ledger"), ("REPORT", "report_html")):
            dest = self.parameterAsFileOutput(parameters, key, context)
            results[key] = str(folder / outputs[name].name) if name in outputs else None
            if dest and name in outputs:
                results[key] = params.deliver_file(outputs[name], dest)
        self.report = results.get("REPORT")  # listed in the Results Viewer after the run
        cumulative = report.get("cumulative") or {}
        for key, (path, _) in NUMBERS.items():
            results[key] = (cumulative.get(path[0]) or {}).get(path[1])
        periods = [
            {k: p.get(k) for k in ("from", "to", "dates", "volume_m3", "uncertainty_m3", "quality")}
            for p in report.get("periods") or []
        ]
        results["PERIODS"] = json.dumps(periods)
        for p in periods:
            v, u = p["volume_m3"], p["uncertainty_m3"]
            feedback.pushInfo(
                f"E{p['from']} → E{p['to']}: net {v['net']:+,.1f} ± {u['net']:,.1f} m³, "
                f"cut {v['cut']:,.1f} ± {u['cut']:,.1f}, fill {v['fill']:,.1f} ± {u['fill']:,.1f}; "
                f"quality: {(p.get('quality') or {}).get('verdict', '–')}"
            )
        return results
