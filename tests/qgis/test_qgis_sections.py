"""The estimate's cross-sections (issue 54, item 4) in QGIS: a line layer as the SECTIONS
parameter reaches the engine, SECTION_PROFILES is its sections.csv with the pictures beside it."""

from __future__ import annotations

import csv

import pytest
from qgis.core import QgsFeature, QgsGeometry, QgsPointXY, QgsProcessingException, QgsVectorLayer


def _lines(x: float, y: float) -> QgsVectorLayer:
    layer = QgsVectorLayer("LineString?crs=EPSG:32654&field=name:string", "sections", "memory")
    feature = QgsFeature(layer.fields())
    feature.setGeometry(QgsGeometry.fromPolylineXY([QgsPointXY(x - 20, y), QgsPointXY(x + 20, y)]))
    feature.setAttributes(["A-A"])
    layer.dataProvider().addFeatures([feature])
    return layer


def test_sections_csv_and_pictures_are_delivered(run_alg, estimate_inputs, truth, tmp_path):
    pile = next(f for f in truth["features"] if f["sign"] > 0)
    dest = tmp_path / "profiles.csv"
    params = {
        **estimate_inputs,
        "SECTIONS": _lines(pile["x"], pile["y"]),
        "DIFFERENCE": str(tmp_path / "difference.tif"),
        "SECTION_PROFILES": str(dest),
    }
    results = run_alg("estimatevolumechange", params)
    assert results["SECTION_PROFILES"] == str(dest)
    with open(dest, newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows and {r["name"] for r in rows} == {"A-A"}
    assert float(rows[-1]["chainage_m"]) == pytest.approx(40.0, abs=0.01)
    rise = max(float(r["after"]) - float(r["before"]) for r in rows if r["after"] and r["before"])
    assert rise == pytest.approx(pile["height"], abs=0.5)
    assert (tmp_path / "profiles" / "A-A.svg").read_text().startswith("<svg")
    uri = f"{dest.as_uri()}?type=csv&detectTypes=yes&geomType=none"
    layer = QgsVectorLayer(uri, "profiles", "delimitedtext")  # the CSV loads in QGIS as a table
    assert layer.isValid() and layer.featureCount() == len(rows)
    chainage = layer.fields().field("chainage_m")
    assert chainage.isNumeric() and max(f["chainage_m"] for f in layer.getFeatures()) == pytest.approx(40.0, abs=0.01)


def test_sections_output_without_lines_is_refused(run_alg, estimate_inputs, tmp_path):
    params = {**estimate_inputs, "DIFFERENCE": str(tmp_path / "d.tif"), "SECTION_PROFILES": str(tmp_path / "s.csv")}
    with pytest.raises(QgsProcessingException, match="Cross-section lines"):
        run_alg("estimatevolumechange", params)
    assert not (tmp_path / "d.tif").exists() and not (tmp_path / "s.csv").exists()
