"""Register the after point cloud onto the before point cloud."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from qgis.core import (
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterFileDestination,
)

from . import engine, optionparams, params
from .base import SoilVolumeAlgorithm

HELP = """\
<p>Aligns the <b>after</b> point cloud onto the <b>before</b> point cloud (rigid 3D transform)
and writes the registered after cloud.</p>
<h3>Method</h3>
<p>The before cloud is cropped to the after footprint plus the <b>crop radius</b>. A coarse
FPFH + RANSAC alignment is tried (in <i>auto</i> mode kept only when it beats the GPS
georeferencing within the GPS error prior), then the <b>fine registration</b> refines it:
robust point-to-plane ICP (default; areas that changed are down-weighted), generalized ICP, or
the paper's PFH + SAC-IA on a patch.</p>
<h3>Inputs</h3>
<p>Before/after clouds as files (LAS, LAZ, PLY, PCD, XYZ/TXT/CSV) or point cloud layers, CRS
overrides for files without one, the crop radius (m), the georeferencing of the surveys and its
prior, and the registration methods.</p>
<h3>Outputs</h3>
<p>The registered after cloud (LAS/LAZ, in the before cloud's CRS), the 4×4 transform
(row-major, absolute coordinates, after → before) as a JSON string and optionally a JSON file,
and the fine stage's fitness and inlier RMSE.</p>"""


class RegisterPointClouds(SoilVolumeAlgorithm):
    """Coarse + fine registration of two clouds."""

    _name = "registerpointclouds"
    _display_name = "Register point clouds (after onto before)"
    _help = HELP
    _tags = "registration,icp,gicp,fpfh,ransac,align,co-registration,point cloud"
    _group = "Point cloud tools"
    _group_id = "pointcloud"
    _clouds = {"BEFORE": "Before", "AFTER": "After"}

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        self.addParameter(params.cloud_param("BEFORE", "Before"))
        self.addParameter(params.cloud_param("AFTER", "After"))
        for param in optionparams.parameters("register"):
            self.addParameter(param)
        self.addParameter(
            QgsProcessingParameterFileDestination(
                "OUTPUT", self.tr("Registered after cloud"), fileFilter=params.LAS_FILTER
            )
        )
        self.addParameter(params.optional_file("TRANSFORM_FILE", self.tr("Transform (JSON)"), "JSON files (*.json)"))
        self.addOutput(
            QgsProcessingOutputString("TRANSFORM", self.tr("Transform (4×4, row-major JSON, after → before)"))
        )
        self.addOutput(QgsProcessingOutputNumber("FITNESS", self.tr("Fine registration fitness")))
        self.addOutput(QgsProcessingOutputNumber("RMSE", self.tr("Fine registration inlier RMSE (m)")))

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        before = params.cloud_path(self, parameters, "BEFORE", context, "Before")
        after = params.cloud_path(self, parameters, "AFTER", context, "After")
        options = optionparams.read_options(self, parameters, context, feedback, "register")
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        if not params.is_las(out):
            out += ".laz"
        args = ["register", before, after, *engine.option_args(options, "register")]
        with params.work_folder() as work:
            moved = work / f"registered{Path(out).suffix.lower()}"
            reg = engine.run([*args, "--out", str(moved)], feedback, hint="Set the 'CRS override' parameters.")
            params.deliver_file(moved, out)
        transform = params.to_json(reg["transform"])
        feedback.pushInfo(f"Transform (after → before): {transform}")
        results: dict[str, Any] = {"OUTPUT": out, "TRANSFORM": transform}
        fine = reg.get("fine") or {}
        results["FITNESS"] = fine.get("fitness")
        results["RMSE"] = fine.get("rmse")
        dest = self.parameterAsFileOutput(parameters, "TRANSFORM_FILE", context)
        if dest:
            params.dest_folder(Path(dest).parent)
            text = params.to_json(reg, indent=2) + "\n"
            params.write_atomically(dest, lambda partial: partial.write_text(text, encoding="utf-8"))
            results["TRANSFORM_FILE"] = dest
        return results
