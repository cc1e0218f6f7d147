"""The estimate's contours (issue 54, item 4) as a Processing output: CONTOURS, a GeoPackage
whose three line layers load into the project in the difference's CRS."""

from __future__ import annotations

import pytest
from qgis.core import (
    Qgis,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingOutputLayerDefinition,
    QgsProject,
    QgsRasterLayer,
    QgsVectorLayer,
)


def test_contours_load_as_three_line_layers(run_alg, estimate_inputs, tmp_path):
    project = QgsProject.instance()
    context = QgsProcessingContext()
    context.setProject(project)
    dest = str(tmp_path / "contours.gpkg")
    params = {
        **estimate_inputs,
        "CONTOUR_INTERVAL": 0.5,
        "DIFFERENCE": str(tmp_path / "difference.tif"),
        "CONTOURS": QgsProcessingOutputLayerDefinition(dest, project),
    }
    results = run_alg("estimatevolumechange", params, context=context)
    assert results["CONTOURS"] == dest
    loads = context.layersToLoadOnCompletion()
    uris = [f"{dest}|layername={name}" for name in ("difference", "dem_before", "dem_after")]
    assert all(uri in loads for uri in uris) and dest not in loads, list(loads)
    crs = QgsRasterLayer(results["DIFFERENCE"], "difference").crs()
    for uri in uris:
        layer = QgsVectorLayer(uri, "contours", "ogr")
        assert layer.isValid() and layer.featureCount() > 0, uri
        assert layer.crs() == crs and layer.geometryType() == Qgis.GeometryType.Line, uri
        assert "ELEV" in layer.fields().names()
    fill = QgsVectorLayer(uris[0], "difference", "ogr")
    for feature in fill.getFeatures():
        assert (feature["change"] == "fill") == (feature["ELEV"] > 0)
    assert loads[uris[0]].name.startswith("Contours of the difference")


def test_contours_without_an_interval_are_refused(run_alg, estimate_inputs, tmp_path):
    params = {**estimate_inputs, "DIFFERENCE": str(tmp_path / "d.tif"), "CONTOURS": str(tmp_path / "c.gpkg")}
    with pytest.raises(QgsProcessingException, match="Contour interval"):
        run_alg("estimatevolumechange", params)
    assert not (tmp_path / "d.tif").exists() and not (tmp_path / "c.gpkg").exists()
