"""The "Stockpile volumes" algorithm headless: a seeded yard (LAS in UTM 33N) with a polygon
layer whose name and density fields are picked; the engine runs out of process."""

from __future__ import annotations

import json

import laspy
import numpy as np
import pyproj
import pytest
from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsVectorLayer
from qgis.PyQt.QtCore import QMetaType

from soilvolume.scenes.yards import stockpile_yard

EAST, NORTH = 500_000.0, 4_000_000.0


@pytest.fixture
def yard_las(tmp_path):
    """(yard, LAS path) of seed 0, one slot per field: a level pile and one on the slope."""
    yard = stockpile_yard(0, columns=1, rows=1)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([EAST, NORTH, 0.0])
    header.add_crs(pyproj.CRS.from_epsg(32633))
    las = laspy.LasData(header)
    las.x, las.y, las.z = yard.x + EAST, yard.y + NORTH, yard.z
    las.write(str(tmp_path / "yard.las"))
    return yard, tmp_path / "yard.las"


def _layer(yard) -> QgsVectorLayer:
    layer = QgsVectorLayer("Polygon?crs=EPSG:32633", "piles", "memory")
    layer.dataProvider().addAttributes(
        [QgsField("label", QMetaType.Type.QString), QgsField("rho", QMetaType.Type.Double)]
    )
    layer.updateFields()
    for p in yard.piles:
        feature = QgsFeature(layer.fields())
        xy = np.asarray(p.polygon.exterior.coords) + [EAST, NORTH]
        feature.setGeometry(QgsGeometry.fromWkt("POLYGON((" + ",".join(f"{x} {y}" for x, y in xy) + "))"))
        feature.setAttributes([p.name, p.density])
        layer.dataProvider().addFeature(feature)
    return layer


def test_stockpile_volumes_with_picked_fields(run_alg, yard_las, tmp_path):
    yard, las = yard_las
    params = {"INPUT": str(las), "PILES": _layer(yard), "NAME_FIELD": "label", "DENSITY_FIELD": "rho"}
    result = run_alg("stockpilevolumes", {**params, "OUTPUT_FOLDER": str(tmp_path / "out")})
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert result["PILES_COUNT"] == 2 and result["REPORT"] == str(tmp_path / "out" / "report.html")
    rows = {r["name"]: r for r in report["piles"]}
    for p in yard.piles:
        if not p.on_slope:
            assert rows[p.name]["volume_m3"] == pytest.approx(p.volume_m3, rel=0.01)
        assert rows[p.name]["tonnes"] == pytest.approx(rows[p.name]["volume_m3"] * p.density, rel=1e-3)
    assert {f.name for f in (tmp_path / "out").iterdir()} == {"report.json", "report.html", "piles.csv", "piles.gpkg"}
