"""Volume from DEM difference: totals, the per-zone table, and the styled loaded output."""

from __future__ import annotations

import numpy as np
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


CELL = 0.5
ROWS, COLS = 60, 80
FILL = (slice(10, 30), slice(5, 35), 2.0)  # rows, columns, height (m): a 2 m block in the west
CUT = (slice(35, 55), slice(45, 75))  # in the east: a ramp from 0.5 m deep, 0.02 m more per column
NODATA_ROWS = 4  # the after DEM's first rows are nodata


def _write_dem(path, z: np.ndarray) -> str:
    profile = dict(driver="GTiff", width=COLS, height=ROWS, count=1, dtype="float64", nodata=-9999.0)
    transform = rasterio.Affine(CELL, 0.0, 500000.0, 0.0, -CELL, 3900030.0)
    with rasterio.open(path, "w", crs="EPSG:32654", transform=transform, **profile) as ds:
        ds.write(np.where(np.isnan(z), -9999.0, z), 1)
    return str(path)


@pytest.fixture
def analytic_dems(tmp_path) -> tuple[str, str, dict]:
    """Two DEMs on rolling ground whose difference is a 2 m block (fill) and a linear ramp (cut):
    the exact volumes in closed form (a linear function's cell-centre sum is its integral)."""
    rows, cols = np.indices((ROWS, COLS), dtype=float)
    before = 60.0 + 0.05 * cols - 0.03 * rows + np.sin(cols / 7.0) + np.cos(rows / 5.0)
    after = before.copy()
    (fr, fc, height), (cr, cc) = FILL, CUT
    after[fr, fc] += height
    after[cr, cc] -= 0.5 + 0.02 * (cols[cr, cc] - cc.start)
    after[:NODATA_ROWS] = np.nan
    cell_area = CELL * CELL
    n_fill = (fr.stop - fr.start) * (fc.stop - fc.start)
    n_cut = (cr.stop - cr.start) * (cc.stop - cc.start)
    fill = height * n_fill * cell_area
    cut = (0.5 + 0.02 * (cc.stop - cc.start - 1) / 2.0) * n_cut * cell_area
    truth = {"fill": fill, "cut": cut, "net": fill - cut, "area": (ROWS - NODATA_ROWS) * COLS * cell_area}
    return _write_dem(tmp_path / "before.tif", before), _write_dem(tmp_path / "after.tif", after), truth


def test_volumes_of_analytic_dems(run_alg, analytic_dems, tmp_path):
    """Exact: fill 300 m3 in the west zone, cut 118.5 m3 in the east, 1,120 m2 compared (the
    after DEM's nodata rows left out), median difference 0. It was only checked for a net above
    0 and against the engine's own number."""
    before, after, truth = analytic_dems
    res = run_alg(
        "volumefromdems",
        {
            "BEFORE": before,
            "AFTER": after,
            "ZONES": zones_layer(before),
            "ZONE_FIELD": "name",
            "OUTPUT": str(tmp_path / "diff.tif"),
            "TABLE": str(tmp_path / "volumes.gpkg"),
        },
    )
    assert (truth["fill"], truth["cut"], truth["area"]) == pytest.approx((300.0, 118.5, 1120.0))
    for key in ("fill", "cut", "net"):
        assert res[f"{key.upper()}_VOLUME"] == pytest.approx(truth[key], rel=1e-9, abs=1e-6), key
    assert res["COMPARED_AREA"] == pytest.approx(truth["area"], rel=1e-9)
    assert res["MEDIAN_DIFFERENCE"] == pytest.approx(0.0, abs=1e-9)
    table = QgsVectorLayer(res["TABLE"], "volumes", "ogr")
    try:
        rows = {r["name"]: r for r in table.getFeatures()}
        assert (rows["west"]["fill"], rows["west"]["cut"]) == pytest.approx((truth["fill"], 0.0), abs=1e-6)
        assert (rows["east"]["fill"], rows["east"]["cut"]) == pytest.approx((0.0, truth["cut"]), abs=1e-6)
    finally:
        del table


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
