"""Models built in Model Builder from the plugin's algorithms (issue 49, item 10): inputs of the
types Model Builder offers for BEFORE and AFTER run, headless and in qgis_process, also where QGIS
has no PDAL provider (this one: it cannot open a LAS file as a layer), and the volumes reach the
model's outputs as a table."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from osgeo import ogr
from qgis.core import (
    QgsApplication,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingModelAlgorithm,
    QgsProcessingModelChildAlgorithm,
    QgsProcessingModelChildParameterSource,
    QgsProcessingModelOutput,
    QgsProcessingModelParameter,
)

from .test_qgis_process import qgis_env, qgis_process  # noqa: F401 - the fixture

# what Model Builder's child dialog offers as model inputs for a parameter of each type (QGIS 3.40's
# QgsProcessingParameterType::acceptedParameterTypes, not exposed to Python)
OFFERED = {
    "file": ("file", "string"),
    "pointcloud": ("pointcloud", "layer", "string", "expression"),
    "layer": ("layer", "raster", "mesh", "vector", "pointcloud", "annotation", "string", "expression"),
}


def gui_model(path: Path) -> Path:
    """A model as an analyst builds it in Model Builder and saves it: one input per survey, of the
    type the child dialog offers for the estimate's BEFORE and AFTER (created from the registry's
    parameter type, as the Inputs panel does), the difference and the volumes table marked as the
    model's outputs."""
    registry = QgsApplication.processingRegistry()
    estimate = registry.algorithmById("soilvolume:estimatevolumechange")
    model = QgsProcessingModelAlgorithm("Volumes of a pair", "Site")
    child = QgsProcessingModelChildAlgorithm("soilvolume:estimatevolumechange")
    child.setChildId("estimate")
    for name, key in (("before", "BEFORE"), ("after", "AFTER")):
        kind = estimate.parameterDefinition(key).type()
        param = registry.parameterType(OFFERED[kind][0]).create(name)
        param.setDescription(name.title())
        model.addModelParameter(param, QgsProcessingModelParameter(name))
        child.addParameterSources(key, [QgsProcessingModelChildParameterSource.fromModelParameter(name)])
    child.addParameterSources("CELL", [QgsProcessingModelChildParameterSource.fromStaticValue(1.0)])
    outputs = {}
    for name, key in (("volumes", "VOLUMES"), ("difference", "DIFFERENCE")):
        outputs[name] = QgsProcessingModelOutput(name, name.title())
        outputs[name].setChildId("estimate")
        outputs[name].setChildOutputName(key)
    child.setModelOutputs(outputs)
    model.addChildAlgorithm(child)
    assert model.toFile(str(path))
    return path


def loaded(path: Path) -> QgsProcessingModelAlgorithm:
    model = QgsProcessingModelAlgorithm()
    assert model.fromFile(str(path))
    return model


def net_of(table: str) -> float:
    source = ogr.Open(table.split("|")[0])
    row = source.GetLayer(0).GetNextFeature()
    return row.GetField("net_m3")


def test_model_builder_offers_file_inputs_for_the_surveys(provider):
    """BEFORE and AFTER are file-typed: Model Builder offers File (and String) inputs for them
    (was: only Point Cloud or Map Layer inputs, which QGIS without PDAL cannot load)."""
    registry = QgsApplication.processingRegistry()
    for name in ("estimatevolumechange", "registerpointclouds", "pointcloudtodem"):
        alg = registry.algorithmById(f"soilvolume:{name}")
        for key in ("BEFORE", "AFTER", "INPUT"):
            if alg.parameterDefinition(key) is not None:
                assert alg.parameterDefinition(key).type() == "file", (name, key)


def test_a_model_built_in_model_builder_runs_and_returns_the_volumes(provider, scene_dir, truth, tmp_path):
    from qgis import processing

    model = loaded(gui_model(tmp_path / "pair.model3"))
    values = {
        "before": str(scene_dir / "before.las"),
        "after": str(scene_dir / "after.las"),
        "volumes": str(tmp_path / "volumes.gpkg"),
        "difference": str(tmp_path / "difference.tif"),
    }
    ok, message = model.checkParameterValues(values, QgsProcessingContext())
    assert ok, message
    results = processing.run(model, values)
    net = net_of(results["volumes"])
    assert net == pytest.approx(results["CHILD_RESULTS"]["estimate"]["NET_VOLUME"])
    assert net == pytest.approx(truth["net"], rel=0.03) and Path(results["difference"]).is_file()


def test_the_model_runs_in_qgis_process(plugin_package, qgis_env, scene_dir, truth, tmp_path):  # noqa: F811
    path = gui_model(tmp_path / "pair.model3")
    run = qgis_process(
        qgis_env,
        "run",
        str(path),
        "--json",
        "--",
        f"before={scene_dir / 'before.las'}",
        f"after={scene_dir / 'after.las'}",
        f"volumes={tmp_path / 'volumes.gpkg'}",
        f"difference={tmp_path / 'difference.tif'}",
    )
    assert run.returncode == 0, run.stderr[-2000:] + run.stdout[-2000:]
    results = json.loads(run.stdout)["results"]
    assert net_of(results["volumes"]) == pytest.approx(truth["net"], rel=0.03)
    assert "Unable to load mesh" not in run.stderr + run.stdout and "Cannot open" not in run.stderr


def test_a_missing_file_in_a_model_is_named(provider, scene_dir, tmp_path):
    from qgis import processing

    model = loaded(gui_model(tmp_path / "pair.model3"))
    values = {"before": str(tmp_path / "gone.las"), "after": str(scene_dir / "after.las")}
    values["difference"] = str(tmp_path / "difference.tif")
    with pytest.raises(QgsProcessingException, match=r"Before point cloud .*gone\.las: file not found"):
        processing.run(model, values)
    assert not (tmp_path / "difference.tif").exists()
