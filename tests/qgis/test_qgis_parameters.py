"""The estimate's parameters come from the engine's option table; inputs, help and wording."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from qgis.core import (
    Qgis,
    QgsApplication,
    QgsProcessingParameterDistance,
    QgsProcessingParameterEnum,
    QgsProcessingParameterNumber,
)

from soilvolume.options import Options, command_fields, option

ESTIMATE = "soilvolume:estimatevolumechange"


@pytest.fixture
def estimate(provider):
    return QgsApplication.processingRegistry().algorithmById(ESTIMATE)


def option_fields():
    """The estimate's options (the stockpile's base and density are the stockpile algorithm's)."""
    return [f for f in command_fields("estimate") if f.name != "keep_registered_cloud"]


def test_every_option_is_a_parameter(estimate):
    from soilvolume_qgis.processing.optiontable import qgis_wording

    for field in option_fields():
        param = estimate.parameterDefinition(field.name.upper())
        assert param is not None, field.name
        assert param.description().startswith(field.metadata["label"]), field.name
        assert param.help() == qgis_wording(field.metadata["help"]), field.name
        assert "--" not in param.help(), field.name


def test_choices_are_string_enums(estimate):
    for field in option_fields():
        if not field.metadata["choices"]:
            continue
        param = estimate.parameterDefinition(field.name.upper())
        assert isinstance(param, QgsProcessingParameterEnum), field.name
        assert param.usesStaticStrings() and param.options() == list(field.metadata["choices"])
        assert param.defaultValue() == field.default


def test_lengths_are_distances_and_ranges_are_kept(estimate):
    for field in option_fields():
        param = estimate.parameterDefinition(field.name.upper())
        if field.metadata["unit"] == "m":
            assert isinstance(param, QgsProcessingParameterDistance), field.name
            assert param.defaultUnit() == Qgis.DistanceUnit.Meters
        if isinstance(param, QgsProcessingParameterNumber) and field.default is not None:
            assert param.minimum() == pytest.approx(field.metadata["lo"]), field.name
            assert param.maximum() == pytest.approx(field.metadata["hi"]), field.name
            assert param.defaultValue() == pytest.approx(field.default), field.name


def test_a_new_option_appears_without_plugin_changes(estimate, monkeypatch):
    from soilvolume_qgis.processing import optiontable

    @dataclass(frozen=True)
    class Wider(Options):
        max_slope: float = option(2.0, "Steepest slope", lo=0.0, hi=10.0, help="steepest slope kept (m per m)")

    monkeypatch.setattr(optiontable, "options_class", lambda: Wider)
    alg = estimate.create({})  # a fresh instance, initAlgorithm run again
    param = alg.parameterDefinition("MAX_SLOPE")
    assert param is not None and param.description().startswith("Steepest slope")
    assert param.help() == "Steepest slope kept (m per m)"


def test_one_required_input_per_epoch(estimate):
    """Each survey is a file-typed input (Model Builder offers File inputs for it: they run without
    PDAL), whose dialog dropdown lists the project's point cloud layers, and raster layers too for
    the estimate's Before (a surface as the reference)."""
    from qgis.core import Qgis, QgsProcessingParameterFile

    after, before = estimate.parameterDefinition("AFTER"), estimate.parameterDefinition("BEFORE")
    for param in (after, before, before.clone(), after.clone()):
        assert isinstance(param, QgsProcessingParameterFile) and param.type() == "file"
        assert not param.flags() & param.FlagOptional
    kinds = {Qgis.ProcessingSourceType(t) for t in before.dropdown().dataTypes()}
    assert kinds == {Qgis.ProcessingSourceType.PointCloud, Qgis.ProcessingSourceType.Raster}
    assert [Qgis.ProcessingSourceType(t) for t in after.dropdown().dataTypes()] == [
        Qgis.ProcessingSourceType.PointCloud
    ]
    assert "*.tif" in before.createFileFilter() and "*.ply" in before.createFileFilter()
    assert "*.tif" not in after.createFileFilter()
    assert isinstance(before.clone(), type(before)) and before.clone().createFileFilter() == before.createFileFilter()
    names = {p.name() for p in estimate.parameterDefinitions()}
    assert not {"BEFORE_LAYER", "AFTER_LAYER"} & names


def test_a_missing_epoch_is_named(run_alg, scene_dir, tmp_path):
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException, match="No after point cloud"):
        run_alg(
            "estimatevolumechange", {"BEFORE": str(scene_dir / "before.las"), "DIFFERENCE": str(tmp_path / "d.tif")}
        )


def test_registered_cloud_is_off_by_default(estimate):
    assert not estimate.parameterDefinition("REGISTERED").createByDefault()


def test_help_is_flowing_html(provider):
    for alg in provider.algorithms():
        text = alg.shortHelpString()
        assert "\n" not in text and "<p>" in text, alg.name()


def test_engine_messages_in_parameter_words(plugin_package):
    """Options the engine names by key are worded as parameters, no flag parsing involved."""
    from soilvolume_qgis.processing import optiontable

    wording = optiontable.engine("core.wording")
    text = optiontable.qgis_wording(f"coarse: skipped (87% within 0.4 m); {wording.opt('coarse', 'fpfh')} forces it")
    assert "{" not in text and "'Coarse registration' (COARSE) = fpfh forces it" in text
    assert text.startswith("Coarse")
    assert "(CELL)" in optiontable.qgis_wording(f"grid too large: use a larger {wording.opt('cell')}")
    assert optiontable.qgis_wording(f"used as georeferenced ({wording.opt('georeferencing')})").endswith(
        "('Georeferencing of the surveys' (GEOREFERENCING))"
    )
    assert optiontable.qgis_wording(f"set {wording.opt('cell')}, then run").endswith("(CELL), then run")
    assert optiontable.qgis_wording("use --overwrite") == "Use --overwrite"  # text without markers is kept
    assert wording.cli(f"use {wording.opt('memory_limit', 4)}") == "use --memory-limit 4"
    page = wording.html(
        f"<style>a{{--x:1}}</style><td>skipped; {wording.opt('coarse', 'fpfh')} forces it &amp; more</td>"
    )
    assert "--coarse fpfh" in page  # the engine's page reads as the command line's
    assert optiontable.reword_html(page) == (
        "<style>a{--x:1}</style><td>skipped; 'Coarse registration' (COARSE) = fpfh forces it &amp; more</td>"
    )


def test_option_errors_name_the_parameter(plugin_package):
    from soilvolume_qgis.processing import optiontable

    class OptionError(Exception):
        field, reason = "radius", "must be between 0 and 10000 m (got -1)"

    text = optiontable.option_error_text(OptionError())
    assert text == (
        "Incorrect parameter value for 'Crop radius around the after footprint' "
        "(RADIUS): must be between 0 and 10000 m (got -1)"
    )
    assert optiontable.option_error_text(ValueError("plain")) is None


def test_a_point_cloud_layer_is_read_from_its_file(estimate, scene_dir):
    """A loaded layer (here a COPC-provider layer object) gives the engine its source file."""
    from qgis.core import QgsPointCloudLayer, QgsProcessingContext
    from soilvolume_qgis.processing import params

    layer = QgsPointCloudLayer(str(scene_dir / "before.las"), "before", "copc")
    path = params.cloud_path(estimate, {"BEFORE": layer}, "BEFORE", QgsProcessingContext(), "Before")
    assert path == str(scene_dir / "before.las")


@pytest.mark.parametrize("algorithm", ["estimatevolumechange", "registerpointclouds", "pointcloudtodem"])
def test_file_pickers_open_on_point_clouds(provider, algorithm):
    """A file dialog opens on its first filter: every cloud input's is the point clouds (was: the
    estimate's Before opened on "DEM GeoTIFF", so a folder of .las/.laz files looked empty); the
    estimate's Before offers the design GeoTIFF as the second choice, a LandXML design third."""
    alg = QgsApplication.processingRegistry().algorithmById(f"soilvolume:{algorithm}")
    for name in ("BEFORE", "AFTER", "INPUT"):
        param = alg.parameterDefinition(name)
        if param is None:
            continue
        for each in (param, param.clone()):  # the dialogs' widgets are built on clones
            filters = each.createFileFilter().split(";;")
            assert filters[0].startswith("Point clouds (") and "*.las" in filters[0] and "*.laz" in filters[0]
            if name == "BEFORE" and algorithm == "estimatevolumechange":
                assert filters[1].startswith("DEM GeoTIFF") and "*.tif" in filters[1], filters
                assert filters[2].startswith("LandXML design (*.xml *.landxml"), filters


def test_a_series_takes_a_design_file_and_its_tolerance(provider, tmp_path):
    """The series' --design is a file picker on GeoTIFF and LandXML designs, read into the engine's Options."""
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback, QgsProcessingParameterFile
    from soilvolume_qgis.processing import optionparams, optiontable

    alg = QgsApplication.processingRegistry().algorithmById("soilvolume:volumeseries").create({})
    param = alg.parameterDefinition("DESIGN")
    assert isinstance(param, QgsProcessingParameterFile) and param.flags() & param.FlagOptional
    assert "*.tif" in param.fileFilter() and "*.xml" in param.fileFilter()
    assert alg.parameterDefinition("TOLERANCE") is not None and alg.parameterDefinition("ZONES") is not None
    design = tmp_path / "design.xml"
    design.write_text("<LandXML/>")
    given = {"DESIGN": str(design), "TOLERANCE": 0.05}
    options = optionparams.read_options(alg, given, QgsProcessingContext(), QgsProcessingFeedback(), "series")
    assert (options.design, options.tolerance) == (str(design), 0.05)
    assert "{" not in optiontable.qgis_wording("{opt:design} x.tif: give {opt:tolerance}")
