"""Point cloud to average-height DEM."""

from __future__ import annotations

from typing import Any

from qgis.core import (
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputNumber,
    QgsProcessingParameterExtent,
    QgsProcessingParameterRasterDestination,
)

from . import engine, optionparams, params, styles
from .base import SoilVolumeAlgorithm

HELP = """\
<p>Grids one point cloud into a GeoTIFF of the average height per cell (the DEMs the volume
method compares).</p>
<h3>Inputs</h3>
<p>A point cloud file (LAS, LAZ, PLY, PCD, XYZ/TXT/CSV) or point cloud layer; a CRS override
when the file has none; the <b>cell size</b> (0 = chosen from the point density, at least 8
points per cell); an optional <b>extent</b> (e.g. another DEM's extent, to get the same grid;
snapped outwards to the cell size); the per-cell <b>statistic</b> (robust mean rejects points
beyond 3 MAD of the cell median) and which points count as <b>ground</b>.</p>
<h3>Output</h3>
<p>A single-band Float32 GeoTIFF in the cloud's projected CRS (a geographic CRS is replaced by
its UTM zone); empty cells are nodata. It loads with a terrain colour ramp.</p>"""


class PointCloudToDem(SoilVolumeAlgorithm):
    """One cloud to an average-height GeoTIFF."""

    _name = "pointcloudtodem"
    _display_name = "Point cloud to average-height DEM"
    _help = HELP
    _tags = "dem,dsm,grid,rasterize,average,height,point cloud,lidar"
    _group = "Point cloud tools"
    _group_id = "pointcloud"
    _clouds = {"INPUT": "Input"}

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        self.addParameter(params.cloud_param("INPUT", "Input"))
        self.addParameter(params.crs_param("CRS", "Input"))
        for param in optionparams.parameters("dem"):
            self.addParameter(param)
        self.addParameter(
            QgsProcessingParameterExtent("EXTENT", self.tr("Grid extent (default: the cloud's)"), optional=True)
        )
        self.addParameter(QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Average-height DEM")))
        for key, description in (
            ("CELL_SIZE", "Cell size (m)"),
            ("ROWS", "Rows"),
            ("COLUMNS", "Columns"),
            ("POINTS", "Points gridded"),
            ("VALID_CELLS", "Cells with a height"),
        ):
            self.addOutput(QgsProcessingOutputNumber(key, self.tr(description)))

    def bounds(self, parameters: dict[str, Any], context: QgsProcessingContext) -> list[str]:
        """The extent parameter as ``--bounds XMIN YMIN XMAX YMAX --bounds-crs CRS`` (the engine
        brings it into the cloud's CRS), or no arguments."""
        if not parameters.get("EXTENT"):
            return []
        crs = self.parameterAsExtentCrs(parameters, "EXTENT", context)
        rect = self.parameterAsExtent(parameters, "EXTENT", context, crs)
        if rect.isEmpty():
            raise QgsProcessingException("The grid extent is empty.")
        box = [repr(v) for v in (rect.xMinimum(), rect.yMinimum(), rect.xMaximum(), rect.yMaximum())]
        text = crs.authid() if crs.authid().upper().startswith("EPSG:") else crs.toWkt()
        return ["--bounds", *box] + (["--bounds-crs", text] if crs.isValid() else [])

    def processAlgorithm(  # noqa: N802
        self,
        parameters: dict[str, Any],
        context: QgsProcessingContext,
        feedback: QgsProcessingFeedback,
    ) -> dict[str, Any]:
        self.check_outputs(parameters, context)
        cloud = params.cloud_path(self, parameters, "INPUT", context, "Input")
        crs = params.crs_text(self, parameters, "CRS", context)
        options = optionparams.read_options(self, parameters, context, feedback, "dem")
        out = params.output_layer(self, parameters, "OUTPUT", context)
        args = ["dem", cloud, *engine.option_args(options, "dem"), *self.bounds(parameters, context)]
        args += ["--crs", crs] if crs else []
        with params.work_folder() as work:
            grid = engine.run(
                [*args, "--out", str(work / "dem.tif")], feedback, hint="Set the 'Input CRS override' parameter."
            )
            params.deliver_raster(work / "dem.tif", out)
        styles.style_on_load(context, out, styles.TERRAIN)
        feedback.pushInfo(
            f"{grid['rows']} x {grid['cols']} cells of {grid['cell_m']} m, {grid['points']:,} "
            f"points, {grid['valid_cells']:,} cells with a height ({grid['crs']})"
        )
        return {
            "OUTPUT": out,
            "CELL_SIZE": float(grid["cell_m"]),
            "ROWS": int(grid["rows"]),
            "COLUMNS": int(grid["cols"]),
            "POINTS": int(grid["points"]),
            "VALID_CELLS": int(grid["valid_cells"]),
        }
