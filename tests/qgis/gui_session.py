"""A desktop QGIS session under a virtual X server, driven by ``test_qgis_gui.py``.

Opens the estimate's Processing dialog, runs the algorithm the way the dialog does (outputs loaded
into the project through Processing's own post-processing), shows the Layers panel and the map,
checks stacking order and legend ranges through the API and saves screenshots.

Usage: gui_session.py PLUGINS_DIR BEFORE AFTER OUT_DIR ARTEFACTS_DIR (prints a JSON summary).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from qgis.core import (
    QgsApplication,
    QgsColorRampLegendNode,
    QgsLayerTreeModel,
    QgsLegendSettings,
    QgsProject,
    QgsRasterLayer,
    QgsRenderContext,
)
from session import start  # tests/qgis/session.py, beside this script


def settle(seconds: float = 0.5) -> None:
    end = time.time() + seconds
    while time.time() < end:
        QgsApplication.processEvents()
        time.sleep(0.02)


def dropdown_layers(wrapper) -> list[str]:
    """The entries of a layer parameter's dropdown (layer names; the source in brackets)."""
    from qgis.PyQt.QtWidgets import QComboBox

    combo = wrapper.wrappedWidget().findChild(QComboBox)
    return [combo.itemText(i) for i in range(combo.count())]


def a_dem_layer(folder: Path) -> QgsRasterLayer:
    """A small DEM GeoTIFF loaded into the project (a design surface to pick as *Before*)."""
    from osgeo import gdal, osr

    path = folder / "design_dem.tif"
    raster = gdal.GetDriverByName("GTiff").Create(str(path), 4, 4, 1, gdal.GDT_Float32)
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32654)
    raster.SetProjection(srs.ExportToWkt())
    raster.SetGeoTransform((500000.0, 1.0, 0.0, 4000004.0, 0.0, -1.0))
    raster.GetRasterBand(1).Fill(60.0)
    raster = None
    layer = QgsRasterLayer(str(path), "design DEM")
    QgsProject.instance().addMapLayer(layer)
    return layer


def dialog_checks(before: str, after: str, artefacts: Path) -> dict:
    """Open the algorithm dialog with the two clouds set; read its widgets; screenshot."""
    from processing.gui.AlgorithmDialog import AlgorithmDialog

    alg = QgsApplication.processingRegistry().createAlgorithmById("soilvolume:estimatevolumechange")
    dialog = AlgorithmDialog(alg)
    panel = dialog.mainWidget()
    panel.setParameters({"BEFORE": before, "AFTER": after})
    dialog.resize(1000, 850)
    dialog.show()
    settle()
    dialog.grab().save(str(artefacts / "estimate_dialog.png"))
    wrappers = panel.wrappers
    from qgis.PyQt.QtWidgets import QDoubleSpinBox, QLabel

    radius = wrappers["RADIUS"].wrappedWidget()
    out = {
        "radius_text": radius.findChild(QDoubleSpinBox).text(),
        "radius_labels": [label.text() for label in radius.findChildren(QLabel)],
        "fine_value": wrappers["FINE"].widgetValue(),
        "before_value": wrappers["BEFORE"].widgetValue(),
        "registered_created": bool(wrappers["REGISTERED"].widgetValue()),
        "before_dropdown": dropdown_layers(wrappers["BEFORE"]),
        "after_dropdown": dropdown_layers(wrappers["AFTER"]),
    }
    dialog.close()
    return out


def opened(algorithm: str, values: dict | None = None):
    """The algorithm's dialog as Processing opens it (``execAlgorithmDialog`` sets ``values``)."""
    from processing.gui.AlgorithmDialog import AlgorithmDialog

    dialog = AlgorithmDialog(QgsApplication.processingRegistry().createAlgorithmById(algorithm))
    if values:
        dialog.setParameters(values)
    dialog.show()
    settle(0.2)
    return dialog


def parameters_or_refusal(dialog) -> dict | str:
    """The parameters the dialog would run with, or the name of the input it refuses to run without."""
    from processing.gui.AlgorithmDialogBase import AlgorithmDialogBase

    try:
        return dialog.mainWidget().createProcessingParameters()
    except AlgorithmDialogBase.InvalidParameterValue as refused:
        return f"refused: {refused.parameter.name()}"


def default_checks(before: str, after: str) -> dict:
    """With a raster layer in the project: what the Before (and After) dropdowns start on, the
    surface dialogs' refusal to run without a choice, and the series dialog's pre-set files."""
    out = {}
    for algorithm, keys in (
        ("soilvolume:estimatevolumechange", ("BEFORE",)),
        ("soilvolume:volumefromdems", ("BEFORE", "AFTER")),
    ):
        dialog = opened(algorithm)
        out[algorithm] = {key: dialog.mainWidget().wrappers[key].widgetValue() for key in keys}
        out[algorithm]["run"] = str(parameters_or_refusal(dialog))[:80]
        dialog.close()
    layer = QgsProject.instance().mapLayersByName("design DEM")[0]
    dialog = opened("soilvolume:volumefromdems", {"BEFORE": layer, "AFTER": layer.id()})
    out["picked"] = {key: dialog.mainWidget().wrappers[key].widgetValue() == layer.id() for key in ("BEFORE", "AFTER")}
    dialog.close()
    dialog = opened("soilvolume:volumeseries", {"EPOCHS": [after, before, after]})
    out["series"] = {"widget": dialog.mainWidget().wrappers["EPOCHS"].widgetValue()}
    run = parameters_or_refusal(dialog)
    out["series"]["run"] = run.get("EPOCHS") if isinstance(run, dict) else run
    dialog.close()
    return out


def run_and_load(before: str, after: str, out_dir: Path) -> dict:
    from processing.tools.general import runAndLoadResults

    rasters = ("DIFFERENCE", "DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET")
    params = {
        "BEFORE": before,
        "AFTER": after,
        "CELL": 1.0,
        **{key: str(out_dir / f"{key.lower()}.tif") for key in rasters},
        "CHANGE_AREAS": "TEMPORARY_OUTPUT",  # what the dialog fills in (created by default)
    }
    return runAndLoadResults("soilvolume:estimatevolumechange", params)


def legend_checks(model: QgsLayerTreeModel) -> list[dict]:
    rows = []
    for node in model.rootGroup().findLayers():
        layer = node.layer()
        if not isinstance(layer, QgsRasterLayer):
            continue
        ramp = [n for n in model.layerLegendNodes(node) if isinstance(n, QgsColorRampLegendNode)]
        data = ramp[0].exportToJson(QgsLegendSettings(), QgsRenderContext()) if ramp else None
        renderer = layer.renderer()
        rows.append(
            {
                "name": layer.name(),
                "legend": [data["min"].toDouble(), data["max"].toDouble()] if data else None,
                "style": [renderer.classificationMin(), renderer.classificationMax()],
                "nodata": layer.dataProvider().sourceNoDataValue(1),
            }
        )
    return rows


def change_area_checks(results: dict) -> dict:
    """The loaded polygons: their volumes per kind, the headline's, the renderer's categories."""
    from qgis.core import QgsVectorLayer

    layers = [x for x in QgsProject.instance().mapLayers().values() if isinstance(x, QgsVectorLayer)]
    if len(layers) != 1:
        return {"layers": [x.name() for x in layers]}
    layer = layers[0]
    sums: dict[str, float] = {}
    for feature in layer.getFeatures():
        sums[feature["kind"]] = sums.get(feature["kind"], 0.0) + feature["volume_m3"]
    renderer = layer.renderer()
    return {
        "layers": [layer.name()],
        "sums": sums,
        "headline": {"cut": results["CUT_VOLUME"], "fill": results["FILL_VOLUME"]},
        "categories": sorted(c.value() for c in getattr(renderer, "categories", list)()),
        "alphas": [
            [s.color().alpha(), s.symbolLayer(0).strokeColor().alpha()] for s in renderer.symbols(QgsRenderContext())
        ],
        "crs": layer.crs().authid(),
    }


def layers_window(artefacts: Path) -> QgsLayerTreeModel:
    """The Layers panel and the map side by side, screenshot saved."""
    from qgis.gui import QgsLayerTreeMapCanvasBridge, QgsLayerTreeView, QgsMapCanvas
    from qgis.PyQt.QtWidgets import QHBoxLayout, QWidget

    project = QgsProject.instance()
    window, row = QWidget(), QHBoxLayout()
    model = QgsLayerTreeModel(project.layerTreeRoot())
    view, canvas = QgsLayerTreeView(), QgsMapCanvas()
    view.setModel(model)
    bridge = QgsLayerTreeMapCanvasBridge(project.layerTreeRoot(), canvas)
    row.addWidget(view, 1)
    row.addWidget(canvas, 2)
    window.setLayout(row)
    window.resize(1200, 700)
    window.show()
    view.expandAll()
    canvas.setDestinationCrs(project.layerTreeRoot().findLayers()[0].layer().crs())
    canvas.zoomToFullExtent()
    canvas.refresh()
    settle(1.0)
    canvas.waitWhileRendering()
    settle(0.5)
    window.grab().save(str(artefacts / "layers_and_map.png"))
    window._keep = (view, canvas, bridge)  # noqa: SLF001 - keep wrappers alive until exit
    return model


def main(plugins_dir: str, before: str, after: str, out_dir: str, artefacts: str) -> int:
    app, _provider, _modules = start(plugins_dir, gui=True)
    folder = Path(artefacts)
    folder.mkdir(parents=True, exist_ok=True)
    design = a_dem_layer(Path(out_dir))  # listed by the dialog's Before dropdown, then removed
    summary = {"dialog": dialog_checks(before, after, folder), "defaults": default_checks(before, after)}
    QgsProject.instance().removeMapLayer(design.id())
    results = run_and_load(before, after, Path(out_dir))
    summary["net"] = results["NET_VOLUME"]
    model = layers_window(folder)
    summary["order"] = [n.layer().name() for n in model.rootGroup().findLayers()]
    summary["legends"] = legend_checks(model)
    summary["change_areas"] = change_area_checks(results)
    print(json.dumps(summary))
    QgsProject.instance().removeAllMapLayers()
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:6]))
