"""A surface as the reference in QGIS: the estimate algorithm takes a DEM raster layer (or a
GeoTIFF) as BEFORE and the engine compares the survey with it (issue 21, item 3)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from qgis.core import QgsRasterLayer

SEED = 3


@pytest.fixture(scope="module")
def design_site(tmp_path_factory):
    from designs import write_surface

    from soilvolume.scenes.synthetic import SceneConfig, make_pair, write_pair

    folder = tmp_path_factory.mktemp("design")
    cfg = SceneConfig.small(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0))
    _, after, truth = write_pair(make_pair(SEED, cfg), folder)
    return write_surface(folder / "design.tif", SEED, cfg, cell=1.0), after, json.loads(truth.read_text())


def test_a_raster_layer_as_before(run_alg, design_site, tmp_path):
    design, after, truth = design_site
    layer = QgsRasterLayer(str(design), "design")
    assert layer.isValid()
    out = {k: str(tmp_path / f"{k.lower()}.tif") for k in ("DIFFERENCE", "DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET")}
    result = run_alg(
        "estimatevolumechange",
        {"BEFORE": layer, "AFTER": str(after), **out, "REPORT_JSON": str(tmp_path / "report.json")},
    )
    for key in ("NET", "CUT", "FILL"):
        assert result[f"{key}_VOLUME"] == pytest.approx(truth[key.lower()], rel=0.02), key
    assert result["VERDICT"] == "reliable", result["QUALITY_MESSAGES"]
    assert "agrees with the design" in result["QUALITY_MESSAGES"]
    report = json.loads(Path(result["REPORT_JSON"]).read_text())
    assert report["reference"]["kind"] == "surface" and report["reference"]["path"] == str(design)
    assert report["reference"]["agreement"]["agrees"] is True  # its sentence is good news, no warning
    assert report["registration"]["kind"] == "none: the reference is a surface"
    dem = QgsRasterLayer(result["DEM_BEFORE"], "dem")
    assert dem.isValid() and dem.crs().authid() == "EPSG:32654"


def test_a_geotiff_path_as_before_and_a_bad_one(run_alg, design_site, tmp_path):
    from qgis.core import QgsProcessingException

    design, after, truth = design_site
    result = run_alg(
        "estimatevolumechange", {"BEFORE": str(design), "AFTER": str(after), "DIFFERENCE": str(tmp_path / "d.tif")}
    )
    assert result["NET_VOLUME"] == pytest.approx(truth["net"], rel=0.02)
    with pytest.raises(QgsProcessingException, match="file not found"):
        run_alg(
            "estimatevolumechange",
            {"BEFORE": str(tmp_path / "missing.tif"), "AFTER": str(after), "DIFFERENCE": str(tmp_path / "e.tif")},
        )


def test_a_landxml_design_as_before(run_alg, design_site, tmp_path):
    """A 0.5 m design's pixel centres as a LandXML TIN, browsed to as BEFORE: the GeoTIFF design's
    volumes within 0.5 %, the reference described as a LandXML TIN."""
    from designs import tin_of, write_landxml, write_surface

    from soilvolume.scenes.synthetic import SceneConfig

    _, after, truth = design_site
    cfg = SceneConfig.small(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0))
    design = write_surface(tmp_path / "design.tif", SEED, cfg, cell=0.5)
    xml = write_landxml(tmp_path / "design.xml", *tin_of(design), epsg=32654)
    runs = {}
    for name, before in (("tif", design), ("xml", xml)):
        runs[name] = run_alg(
            "estimatevolumechange",
            {"BEFORE": str(before), "AFTER": str(after), "REPORT_JSON": str(tmp_path / f"{name}.json")},
        )
    for key in ("CUT", "FILL"):
        assert runs["xml"][f"{key}_VOLUME"] == pytest.approx(runs["tif"][f"{key}_VOLUME"], rel=0.005), key
    assert runs["xml"]["NET_VOLUME"] == pytest.approx(truth["net"], rel=0.02)
    report = json.loads(Path(runs["xml"]["REPORT_JSON"]).read_text())
    assert report["reference"]["format"] == "LandXML TIN" and report["reference"]["path"] == str(xml)


def _model(before_param) -> object:
    """A Model Builder model: its two inputs feed the estimate, whose difference is the model's output."""
    from qgis.core import (
        QgsProcessingModelAlgorithm,
        QgsProcessingModelChildAlgorithm,
        QgsProcessingModelChildParameterSource,
        QgsProcessingModelOutput,
        QgsProcessingModelParameter,
        QgsProcessingParameterFile,
    )

    model = QgsProcessingModelAlgorithm("Survey against design", "tests")
    model.addModelParameter(before_param, QgsProcessingModelParameter(before_param.name()))
    survey = QgsProcessingParameterFile("survey", "Survey")  # a file: this QGIS has no PDAL provider to load LAS
    model.addModelParameter(survey, QgsProcessingModelParameter("survey"))
    child = QgsProcessingModelChildAlgorithm("soilvolume:estimatevolumechange")
    child.setChildId("estimate")
    for key, source in (("BEFORE", before_param.name()), ("AFTER", "survey")):
        child.addParameterSources(key, [QgsProcessingModelChildParameterSource.fromModelParameter(source)])
    output = QgsProcessingModelOutput("difference", "Difference")
    output.setChildId("estimate")
    output.setChildOutputName("DIFFERENCE")
    child.setModelOutputs({"difference": output})
    model.addChildAlgorithm(child)
    return model


def test_a_model_feeds_a_raster_input_to_before(provider, design_site, tmp_path):
    """Model Builder: a model whose raster input feeds *Before* runs, and its output raster holds the net."""
    from qgis import processing
    from qgis.core import QgsProcessingContext, QgsProcessingParameterRasterLayer

    design, after, truth = design_site
    model = _model(QgsProcessingParameterRasterLayer("design", "Design"))
    values = {"design": str(design), "survey": str(after), "difference": str(tmp_path / "model_dod.tif")}
    checked = model.checkParameterValues(values, QgsProcessingContext())
    assert checked[0], checked
    result = processing.run(model, values)
    difference = QgsRasterLayer(next(v for k, v in result.items() if k.endswith("difference")), "difference")
    assert difference.isValid() and difference.crs().authid() == "EPSG:32654"
    stats = difference.dataProvider().bandStatistics(1)
    cell = difference.rasterUnitsPerPixelX() * difference.rasterUnitsPerPixelY()
    assert stats.sum * cell == pytest.approx(truth["net"], rel=0.03)  # the model's raster holds the net change


def test_the_agreement_with_the_design_is_information_not_a_warning(plugin_package):
    """A run against a design whose verdict is 'use with caution' for another reason: its first
    sentence, the survey's agreement with the design, goes to the log as information (was: a
    WARNING); the caution that follows stays a warning."""
    from soilvolume_qgis.processing import estimate_outputs
    from soilvolume_qgis.processing.estimatevolumechange import EstimateVolumeChange

    from .recording import RecordingFeedback

    agrees = "The survey agrees with the design over 900 m² of unchanged ground"
    caution = "Little stable ground surrounds the works"
    report = {"reference": {"agreement": {"agrees": True}}}
    results = {"VERDICT": "use with caution", "QUALITY_MESSAGES": f"{agrees}\n{caution}", "SIGNIFICANCE": "s"}
    feedback = RecordingFeedback()
    EstimateVolumeChange.log_summary(results, feedback, estimate_outputs.good_news(report))
    assert agrees in feedback.infos and feedback.warnings == [caution], (feedback.infos, feedback.warnings)
    assert estimate_outputs.good_news({"reference": {"agreement": {"agrees": False}}}) == 0
    assert estimate_outputs.good_news({}) == 0
