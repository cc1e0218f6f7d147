"""The on-grade classes against a design (issue 54, item 2) as a Processing output: GRADE, the
engine's grade.tif (1 cut to go, 2 on grade, 3 fill to go, 255 not compared), written when the
On-grade tolerance is set, copied out, styled and loaded with the run's layers."""

from __future__ import annotations

import json
from importlib import import_module

import numpy as np
import pytest
from designs import write_surface
from osgeo import gdal
from qgis.core import (
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingOutputLayerDefinition,
    QgsProject,
    QgsRasterLayer,
)

from soilvolume.scenes.synthetic import SceneConfig, make_pair, write_pair

SEED = 3  # the design tests' seed

TOLERANCE = 0.05


@pytest.fixture(scope="module")
def design_pair(tmp_path_factory):
    """(design GeoTIFF, after LAS) of the design tests' seed."""
    folder = tmp_path_factory.mktemp("grade")
    cfg = SceneConfig.small(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0))
    _, after, _ = write_pair(make_pair(SEED, cfg), folder)
    return write_surface(folder / "design.tif", SEED, cfg, cell=1.0), after


def test_grade_is_a_loaded_output_with_a_tolerance(run_alg, plugin_package, design_pair, tmp_path):
    """GRADE copied to its destination on the difference's grid, its classes those report.json
    counts (the share on grade), styled as three classes and loaded with the run's layers."""
    styles = import_module("soilvolume_qgis.processing.styles")  # the plugin as QGIS imports it
    design, after = design_pair
    project, context = QgsProject.instance(), QgsProcessingContext()
    context.setProject(project)
    dest = str(tmp_path / "grade.tif")
    params = {
        "BEFORE": str(design),
        "AFTER": str(after),
        "TOLERANCE": TOLERANCE,
        "DIFFERENCE": str(tmp_path / "difference.tif"),
        "GRADE": QgsProcessingOutputLayerDefinition(dest, project),
        "REPORT_JSON": str(tmp_path / "report.json"),
    }
    results = run_alg("estimatevolumechange", params, context=context)
    assert results["GRADE"] == dest
    grade, diff = gdal.Open(dest), gdal.Open(results["DIFFERENCE"])
    assert grade.GetGeoTransform() == diff.GetGeoTransform() and grade.GetProjection() == diff.GetProjection()
    values = grade.GetRasterBand(1).ReadAsArray()
    assert set(np.unique(values).tolist()) <= {1, 2, 3, 255} and grade.GetRasterBand(1).GetNoDataValue() == 255
    summary = json.loads((tmp_path / "report.json").read_text())["grade"]
    compared = values != 255
    assert summary["tolerance_m"] == TOLERANCE
    assert (values[compared] == 2).mean() == pytest.approx(summary["on_grade_share"], abs=1e-9)
    assert 0 < summary["on_grade_share"] < 1 and (values == 1).any() and (values == 3).any()
    loads = context.layersToLoadOnCompletion()
    assert dest in loads and loads[dest].name.startswith("Grade: cut to go, on grade, fill to go"), list(loads)
    layer = QgsRasterLayer(dest, "grade")
    assert layer.isValid() and layer.crs().authid() == "EPSG:32654"
    assert styles.apply_style(layer, styles.GRADE) and layer.renderer().type() == "paletted"
    assert [c.value for c in layer.renderer().classes()] == [1, 2, 3]


def test_no_grade_without_a_tolerance(run_alg, design_pair, tmp_path):
    """Without a tolerance the default (temporary) GRADE is none and nothing is loaded for it; a
    file asked for without one is refused before any work, nothing written."""
    design, after = design_pair
    project, context = QgsProject.instance(), QgsProcessingContext()
    context.setProject(project)
    params = {"BEFORE": str(design), "AFTER": str(after), "DIFFERENCE": str(tmp_path / "d.tif")}
    results = run_alg("estimatevolumechange", params, context=context)
    assert results["GRADE"] is None and not any("Grade" in d.name for d in context.layersToLoadOnCompletion().values())
    asked = {**params, "DIFFERENCE": str(tmp_path / "e.tif"), "GRADE": str(tmp_path / "g.tif")}
    with pytest.raises(QgsProcessingException, match="On-grade tolerance"):
        run_alg("estimatevolumechange", asked)
    assert not (tmp_path / "e.tif").exists() and not (tmp_path / "g.tif").exists()
