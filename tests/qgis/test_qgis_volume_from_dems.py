"""Volume from DEM difference: totals, the per-zone table, and the styled loaded output."""

from __future__ import annotations

import pytest
import rasterio
from qgis.core import (
    QgsFeature,
    QgsField,
    QgsGeometry,
    QgsProject,
    QgsRasterLayer,
    QgsSingleBandPseudoColorRenderer,
    QgsVectorLayer,
)
from qgis.PyQt.QtCore import QMetaType


def zones_layer(dem: str) -> QgsVectorLayer:
    """Two polygons, west and east halves, that together cover the whole DEM."""
    with rasterio.open(dem) as ds:
        left, bottom, right, top = ds.bounds
    middle = (left + right) / 2
    layer = QgsVectorLayer("Polygon?crs=EPSG:32654", "zones", "memory")
    provider = layer.dataProvider()
    provider.addAttributes([QgsField("name", QMetaType.Type.QString)])
    layer.updateFields()
    for name, (x0, x1) in (("west", (left - 5, middle)), ("east", (middle, right + 5))):
        feature = QgsFeature(layer.fields())
        feature.setGeometry(
            QgsGeometry.fromWkt(
                f"POLYGON(({x0} {bottom - 5},{x1} {bottom - 5},{x1} {top + 5},{x0} {top + 5},{x0} {bottom - 5}))"
            )
        )
        feature.setAttributes([name])
        provider.addFeature(feature)
    return layer


@pytest.fixture
def dems(estimate_run) -> tuple[str, str]:
    return estimate_run["DEM_BEFORE"], estimate_run["DEM_AFTER"]


def test_totals_and_zone_table(run_alg, dems, estimate_run, tmp_path):
    zones = zones_layer(dems[0])
    res = run_alg(
        "volumefromdems",
        {
            "BEFORE": dems[0],
            "AFTER": dems[1],
            "ZONES": zones,
            "ZONE_FIELD": "name",
            "OUTPUT": str(tmp_path / "diff.tif"),
            "TABLE": str(tmp_path / "volumes.gpkg"),
        },
    )
    # the uncorrected difference of the estimate's own DEMs gives its uncompensated volume
    assert res["NET_VOLUME"] == pytest.approx(estimate_run["UNCOMPENSATED_NET_VOLUME"], rel=0.02)
    assert res["FILL_VOLUME"] - res["CUT_VOLUME"] == pytest.approx(res["NET_VOLUME"])
    table = QgsVectorLayer(res["TABLE"], "volumes", "ogr")
    try:
        assert table.isValid()
        assert [f.name() for f in table.fields()][-6:] == ["zone", "name", "cut", "fill", "net", "area"]
        rows = list(table.getFeatures())
        assert sorted(r["name"] for r in rows) == ["east", "west"]
        for key, total in (
            ("cut", "CUT_VOLUME"),
            ("fill", "FILL_VOLUME"),
            ("net", "NET_VOLUME"),
            ("area", "COMPARED_AREA"),
        ):
            assert sum(r[key] for r in rows) == pytest.approx(res[total], rel=1e-6), key
    finally:
        del table
    layer = QgsRasterLayer(res["OUTPUT"], "diff")
    try:
        assert layer.isValid() and layer.crs().authid() == "EPSG:32654"
    finally:
        del layer


def test_without_zones(run_alg, dems, tmp_path):
    res = run_alg(
        "volumefromdems",
        {"BEFORE": dems[0], "AFTER": dems[1], "OUTPUT": str(tmp_path / "d.tif"), "TABLE": str(tmp_path / "v.gpkg")},
    )
    assert res["NET_VOLUME"] > 0 and res["COMPARED_AREA"] > 3000
    table = QgsVectorLayer(res["TABLE"], "volumes", "ogr")
    try:
        rows = list(table.getFeatures())
        assert [r["name"] for r in rows] == ["total"]
        assert rows[0]["net"] == pytest.approx(res["NET_VOLUME"])
    finally:
        del table


def test_loaded_difference_is_styled_around_zero(provider, dems):
    from qgis import processing

    project = QgsProject.instance()
    res = processing.runAndLoadResults(
        "soilvolume:volumefromdems", {"BEFORE": dems[0], "AFTER": dems[1], "OUTPUT": "TEMPORARY_OUTPUT"}
    )
    try:
        layer = project.mapLayer(res["OUTPUT"]) or next(
            lyr for lyr in project.mapLayers().values() if lyr.source() == res["OUTPUT"]
        )
        renderer = layer.renderer()
        assert isinstance(renderer, QgsSingleBandPseudoColorRenderer)
        assert renderer.classificationMin() == pytest.approx(-renderer.classificationMax())
        assert renderer.classificationMax() > 0.5
        ramp = renderer.shader().rasterShaderFunction().colorRampItemList()
        assert ramp[0].color.red() > ramp[0].color.blue()  # cut in red
        assert ramp[-1].color.blue() > ramp[-1].color.red()  # fill in blue
    finally:
        project.removeAllMapLayers()
