"""The estimate's numbers, strings and per-zone tables (layer and CSV) as Processing outputs; the rasters' CRS,
nodata, stacking order and legends once Processing loads them."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from qgis.core import (
    QgsColorRampLegendNode,
    QgsFeature,
    QgsField,
    QgsGeometry,
    QgsLayerTreeModel,
    QgsLegendSettings,
    QgsPointXY,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputLayerDefinition,
    QgsProject,
    QgsRasterLayer,
    QgsRenderContext,
    QgsVectorFileWriter,
    QgsVectorLayer,
)
from qgis.PyQt.QtCore import QMetaType

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
ZONES = {"pile A": (500067.0, 3900087.0, 11.0), "pit": (500068.0, 3900061.0, 7.0)}
STABLE = (
    (500050, 3900042, 500060, 3900050),
    (500105, 3900042, 500117, 3900050),  # ground away from
    (500050, 3900097, 500056, 3900105),
    (500105, 3900097, 500117, 3900104),  # the piles and pit
    (500050, 3900070, 500058, 3900080),
    (500105, 3900072, 500118, 3900080),
)


def write_polygons(path: Path, boxes: dict[str, tuple[float, float, float, float]]) -> Path:
    """A GeoPackage of named rectangles (EPSG:32654)."""
    layer = QgsVectorLayer("Polygon?crs=EPSG:32654", "zones", "memory")
    layer.dataProvider().addAttributes([QgsField("name", QMetaType.Type.QString)])
    layer.updateFields()
    for name, (x0, y0, x1, y1) in boxes.items():
        feature = QgsFeature(layer.fields())
        ring = [QgsPointXY(x0, y0), QgsPointXY(x1, y0), QgsPointXY(x1, y1), QgsPointXY(x0, y1)]
        feature.setGeometry(QgsGeometry.fromPolygonXY([ring]))
        feature.setAttributes([name])
        layer.dataProvider().addFeature(feature)
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "GPKG"
    error = QgsVectorFileWriter.writeAsVectorFormatV3(
        layer, str(path), QgsProject.instance().transformContext(), options
    )
    assert error[0] == QgsVectorFileWriter.NoError, error
    return path


@pytest.fixture(scope="module")
def zoned_run(run_alg_session, scene_dir, tmp_path_factory):
    """One estimate with zones and a stable-ground mask, its outputs loaded into the project."""
    out = tmp_path_factory.mktemp("zoned")
    zones = write_polygons(out / "zones.gpkg", {n: (x - h, y - h, x + h, y + h) for n, (x, y, h) in ZONES.items()})
    stable = write_polygons(out / "stable.gpkg", {f"s{i}": box for i, box in enumerate(STABLE)})
    context = QgsProcessingContext()
    context.setProject(QgsProject.instance())
    loaded = {
        key: QgsProcessingOutputLayerDefinition(str(out / f"{key.lower()}.tif"), QgsProject.instance())
        for key in ("DIFFERENCE", "DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET")
    }
    params = {
        "BEFORE": str(scene_dir / "before.las"),
        "AFTER": str(scene_dir / "after.las"),
        "CELL": 1.0,
        "ZONES": str(zones),
        "STABLE_MASK": str(stable),
        "ZONE_VOLUMES": str(out / "zone_volumes.gpkg"),
        "ZONES_CSV": str(out / "tables" / "per zone.csv"),
        "REPORT_JSON": str(out / "report.json"),
        **loaded,
    }
    results = run_alg_session("estimatevolumechange", params, context=context)
    return results, context


def test_numbers_and_strings(zoned_run, truth):
    results, _ = zoned_run
    report = json.loads(Path(results["REPORT_JSON"]).read_text())
    assert results["NET_UNCERTAINTY"] == pytest.approx(report["uncertainty_m3"]["net"])
    assert results["NET_UNCERTAINTY"] > 0
    assert results["CUT_UNCERTAINTY"] > 0 and results["FILL_UNCERTAINTY"] > 0
    for key, field in (
        ("ALL_CELLS_NET_VOLUME", "net"),
        ("ALL_CELLS_CUT_VOLUME", "cut"),
        ("ALL_CELLS_FILL_VOLUME", "fill"),
    ):
        assert results[key] == pytest.approx(report["volume_all_cells_m3"][field]), key
    assert results["CHANGE_AREA"] == pytest.approx(report["volume_m3"]["area_m2"])
    assert results["ALL_CELLS_NET_UNCERTAINTY"] == pytest.approx(report["uncertainty_m3"]["net_all_cells"])
    assert results["VERDICT"] in ("reliable", "use with caution", "not reliable")
    assert results["LEVEL_OF_DETECTION"] == pytest.approx(report["uncertainty_m3"]["lod_m"])
    # measured +4.6 % (the stable mask's six boxes leave the correction less ground than the
    # automatic choice, which gives -0.58 %); it was 10 %
    assert results["NET_VOLUME"] == pytest.approx(truth["net"], rel=0.07)
    assert "is a significant gain (fill)" in results["SIGNIFICANCE"]
    assert isinstance(results["VERDICT"], str) and isinstance(results["QUALITY_MESSAGES"], str)
    assert report["options"]["stable_mask"] and report["options"]["zones"]


def test_registration_as_rotation_and_shift(zoned_run, truth):
    results, _ = zoned_run
    mis = truth["misalignment"]  # the GPS error the registration undoes
    # measured 2.0309 deg for 2.0322 and 2.527 m for 2.518 m (it was 0.1 deg and 1 m)
    assert results["ROTATION"] == pytest.approx(math.hypot(*mis["rotation_deg"]), abs=0.02)
    assert results["SHIFT"] == pytest.approx(math.hypot(*mis["shift_m"]), abs=0.05)


def test_per_zone_table(zoned_run, truth):
    results, _ = zoned_run
    layer = QgsVectorLayer(results["ZONE_VOLUMES"], "zones", "ogr")
    rows = {f["name"]: f for f in layer.getFeatures()}
    assert set(rows) == set(ZONES)
    for row in rows.values():
        assert row["net_m3"] == pytest.approx(row["fill_m3"] - row["cut_m3"])
        assert row["net_pm_m3"] > 0 and row.hasGeometry()
    pile_a = next(f for f in truth["features"] if f["name"].startswith("pile A"))
    pit = next(f for f in truth["features"] if f["name"].startswith("pit"))
    # measured pile A +0.55 % (it was 15 %), the pit's cut -6.0 % (it was only negative)
    assert rows["pile A"]["net_m3"] == pytest.approx(pile_a["volume"], rel=0.03)
    assert rows["pit"]["cut_m3"] == pytest.approx(pit["volume"], rel=0.1)
    assert rows["pit"]["net_m3"] < 0


def test_per_zone_csv_is_an_output(zoned_run):
    """ZONES_CSV: the engine's zones.csv, a row per zone with the layer's volumes and the ends of
    each interval (the layer's net ± as their half-difference)."""
    results, _ = zoned_run
    assert results["ZONES_CSV"].endswith("per zone.csv")
    with open(results["ZONES_CSV"], newline="", encoding="utf-8") as f:
        rows = {r["name"]: r for r in csv.DictReader(f)}
    layer = {f["name"]: f for f in QgsVectorLayer(results["ZONE_VOLUMES"], "zones", "ogr").getFeatures()}
    assert set(rows) == set(ZONES) == set(layer)
    for name, row in rows.items():
        for field in ("net_m3", "cut_m3", "fill_m3"):
            assert float(row[field]) == pytest.approx(layer[name][field]), (name, field)
        half = (float(row["net_high_m3"]) - float(row["net_low_m3"])) / 2
        assert half == pytest.approx(layer[name]["net_pm_m3"])


def test_per_zone_csv_without_zones_is_refused(run_alg, estimate_inputs, tmp_path):
    params = {**estimate_inputs, "DIFFERENCE": str(tmp_path / "d.tif"), "ZONES_CSV": str(tmp_path / "z.csv")}
    with pytest.raises(QgsProcessingException, match=r"Volumes per zone \(CSV\): give the Zones"):
        run_alg("estimatevolumechange", params)
    assert not (tmp_path / "d.tif").exists() and not (tmp_path / "z.csv").exists()


def test_difference_on_top_and_legends_match_the_style(zoned_run):
    """The post-processors Processing runs after loading: sort keys put the difference on top;
    the Layers-panel legend (layer tree model) shows the styled range, not the QML's."""
    _, context = zoned_run
    details = {d.name: d for d in context.layersToLoadOnCompletion().values()}
    keys = {name: d.layerSortKey for name, d in details.items()}
    assert max(keys, key=keys.get).startswith("Difference")
    project = QgsProject.instance()
    model = QgsLayerTreeModel(project.layerTreeRoot())
    try:
        for path, d in context.layersToLoadOnCompletion().items():
            layer = QgsRasterLayer(path, d.name)
            project.addMapLayer(layer)
            d.postProcessor().postProcessLayer(layer, context, QgsProcessingFeedback())
            lo, hi = legend_range(model, layer)
            renderer = layer.renderer()
            assert (lo, hi) == pytest.approx((renderer.classificationMin(), renderer.classificationMax()))
            assert layer.dataProvider().sourceNoDataValue(1) == -9999
    finally:
        project.removeAllMapLayers()


def legend_range(model: QgsLayerTreeModel, layer) -> tuple[float, float]:
    """(min, max) the colour-ramp legend node of ``layer`` shows."""
    node = model.rootGroup().findLayer(layer.id())
    for legend in model.layerLegendNodes(node):
        if isinstance(legend, QgsColorRampLegendNode):
            data = legend.exportToJson(QgsLegendSettings(), QgsRenderContext())
            return data["min"].toDouble(), data["max"].toDouble()
    raise AssertionError(f"{layer.name()}: no colour ramp legend")


@pytest.mark.skipif(not (REAL / "autzen_bmx_2010.las").is_file(), reason="real data not present")
def test_autzen_rasters_have_no_vertical_crs_in_feet(run_alg, tmp_path):
    """Autzen's z is in US survey feet (NAVD88 ftUS); the rasters hold metres, so they carry
    the horizontal CRS only."""
    res = run_alg(
        "estimatevolumechange",
        {
            "BEFORE": str(REAL / "autzen_bmx_2010.las"),
            "AFTER": str(REAL / "autzen_bmx_2023.las"),
            "DIFFERENCE": str(tmp_path / "d.tif"),
            "DEM_BEFORE": str(tmp_path / "b.tif"),
        },
    )
    for key in ("DIFFERENCE", "DEM_BEFORE"):
        layer = QgsRasterLayer(res[key], key)
        try:
            crs = layer.crs()
            assert crs.isValid() and "ftUS" not in crs.toWkt() and "NAVD88" not in crs.toWkt()
            assert "Oregon" in crs.description()
        finally:
            del layer
    import rasterio

    with rasterio.open(res["DEM_BEFORE"]) as ds:
        dem = ds.read(1, masked=True)
    assert 125 < float(np.ma.median(dem)) < 135  # metres (the file's feet would be ~427)
    assert "REGISTERED" not in res or res["REGISTERED"] is None


def test_quality_messages_name_parameters_not_flags(real_dir, run_alg_session, tmp_path):
    """On Autzen the verdict explains an uncorrected offset and how to ask for registration: in
    QGIS's words (the parameter's label and name), never a command-line flag."""
    params = {
        "BEFORE": str(real_dir / "autzen_bmx_2010.las"),
        "AFTER": str(real_dir / "autzen_bmx_2023.las"),
        "DIFFERENCE": str(tmp_path / "difference.tif"),
    }
    results = run_alg_session("estimatevolumechange", params)
    assert results["VERDICT"] == "use with caution"
    assert "--" not in results["QUALITY_MESSAGES"]
    assert "(GEOREFERENCING)" in results["QUALITY_MESSAGES"]


def test_two_runs_of_a_pair_are_two_groups_with_the_polygons_on_top(provider, scene_dir, tmp_path):
    """Processing's own loading (runAndLoadResults) of two runs of one pair: two groups, each
    run's layers named apart, in each group the change-area polygons on top of the opaque
    difference, outlined with a light fill (were: one group holding both runs' layers under
    the same names, the polygons under the difference)."""
    from qgis import processing

    project = QgsProject.instance()
    before = set(project.mapLayers())
    try:
        for run in (1, 2):
            params = {
                "BEFORE": str(scene_dir / "before.las"),
                "AFTER": str(scene_dir / "after.las"),
                "CELL": 1.0,
                "DIFFERENCE": str(tmp_path / f"difference{run}.tif"),
                "CHANGE_AREAS": str(tmp_path / f"areas{run}.gpkg"),
            }
            processing.runAndLoadResults("soilvolume:estimatevolumechange", params)
        root = project.layerTreeRoot()
        groups = {g.name(): [n.layer().name() for n in g.findLayers()] for g in root.findGroups()}
        ours = {name: layers for name, layers in groups.items() if name.startswith("Soil volume: before → after")}
        assert len(ours) == 2, groups
        for layers in ours.values():  # this session's earlier runs of the pair number them on
            assert [name.split(" (")[0] for name in layers] == ["Areas of significant change", "Difference"], groups
        names = [name for layers in ours.values() for name in layers]
        assert len(set(names)) == 4 and sum(", run " in name for name in names) >= 2, groups
        areas = [layer for layer in project.mapLayers().values() if isinstance(layer, QgsVectorLayer)]
        for layer in areas:
            for symbol in layer.renderer().symbols(QgsRenderContext()):
                assert symbol.color().alpha() <= 64, layer.name()  # a light fill: the difference shows through
                assert symbol.symbolLayer(0).strokeColor().alpha() == 255 and symbol.symbolLayer(0).strokeWidth() >= 0.5
    finally:
        project.removeMapLayers([layer for layer in project.mapLayers() if layer not in before])
        for group in project.layerTreeRoot().findGroups():
            project.layerTreeRoot().removeChildNode(group)


def test_the_refilled_cells_are_an_output(estimate_run, provider):
    """The refilled-cell mask the engine writes (filled_mask.tif) is a QGIS output too (was: none):
    off by default, on the difference's grid, 1 where a height was interpolated, 0 elsewhere; the
    help says what it holds."""
    from osgeo import gdal
    from qgis.core import QgsApplication

    alg = QgsApplication.processingRegistry().algorithmById("soilvolume:estimatevolumechange")
    param = alg.parameterDefinition("FILLED_MASK")
    assert param is not None and not param.createByDefault() and "Refilled cells" in param.description()
    assert "refilled cells" in alg.shortHelpString()
    mask, diff = (gdal.Open(estimate_run[k]) for k in ("FILLED_MASK", "DIFFERENCE"))
    assert mask.GetGeoTransform() == diff.GetGeoTransform()
    assert (mask.RasterXSize, mask.RasterYSize) == (diff.RasterXSize, diff.RasterYSize)
    values = mask.GetRasterBand(1).ReadAsArray()
    assert set(values.ravel().tolist()) <= {0, 1} and values.sum() > 0, set(values.ravel().tolist())
    from soilvolume_qgis.processing import styles

    layer = QgsRasterLayer(estimate_run["FILLED_MASK"], "mask")
    assert styles.apply_style(layer, styles.MASK) and layer.renderer().type() == "paletted"
