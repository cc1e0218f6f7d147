"""The stockpile inventory's outputs and inputs: piles.gpkg (loads with pyogrio, its
CRS and attributes), piles.csv, report.json's rows, and toe polygons read from a vector file."""

from __future__ import annotations

import csv
import json

import numpy as np
import pyogrio
import pyproj
import pytest
import shapely
from pyogrio import raw

from soilvolume.scenes.yards import radial
from soilvolume.stockpile import Pile, PileError, stockpile_inventory, survey_from_points
from soilvolume.stockpile.reader import local_piles, read_piles
from soilvolume.stockpile.writers import COLUMNS, report_piles, write_csv, write_gpkg

ORIGIN = (500_000.0, 4_000_000.0, 0.0)
CRS = pyproj.CRS.from_epsg(32633).to_wkt()


@pytest.fixture(scope="module")
def two_piles():
    """(survey, inventory) of two cones on level ground, the survey in UTM 33N."""
    rng = np.random.default_rng(7)
    x, y = rng.uniform(0, 60, 120_000), rng.uniform(0, 30, 120_000)
    cones = [radial(cx, 15.0, 6.0, np.zeros(3), np.zeros(3), 4.0, 4.0) for cx in (15.0, 45.0)]
    z = 20 + sum(h(x, y) for h, _, _ in cones) + rng.normal(0, 0.02, x.size)
    survey = survey_from_points(x, y, z, origin=ORIGIN, crs_wkt=CRS)
    piles = [Pile(cones[0][1].buffer(1.5), "sand", 1.6), Pile(cones[1][1].buffer(1.5), "", None)]
    return survey, stockpile_inventory(survey, piles)


def test_piles_gpkg_loads_with_its_crs_and_attributes(two_piles, tmp_path):
    survey, inv = two_piles
    path = write_gpkg(tmp_path / "piles.gpkg", inv, survey.grid)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["piles.gpkg"]  # nothing left beside it
    meta, _fids, wkb, values = raw.read(str(path), return_fids=True)
    assert (
        pyogrio.read_info(str(path))["driver"] == "GPKG" and pyproj.CRS.from_user_input(meta["crs"]).to_epsg() == 32633
    )
    props = [dict(zip(meta["fields"], [v[k] for v in values], strict=True)) for k in range(len(wkb))]
    assert [p["name"] for p in props] == ["sand", "pile 2"]
    assert list(meta["fields"]) == list(COLUMNS)
    assert props[0]["volume_m3"] == pytest.approx(inv.piles[0].volume_m3, abs=1e-3)
    assert props[0]["tonnes"] == pytest.approx(inv.piles[0].volume_m3 * 1.6, abs=1e-2)
    assert props[1]["tonnes"] is None or np.isnan(props[1]["tonnes"])
    geom = shapely.from_wkb(wkb[0])
    moved = shapely.affinity.translate(inv.piles[0].polygon, ORIGIN[0], ORIGIN[1])
    assert geom.symmetric_difference(moved).area < 1e-6 * moved.area
    meta = pyogrio.read_info(str(path), layer="piles")
    assert meta["features"] == 2 and meta["geometry_type"] == "MultiPolygon"


def test_piles_csv_and_report_rows(two_piles, tmp_path):
    _, inv = two_piles
    rows = list(csv.DictReader(open(write_csv(tmp_path / "piles.csv", inv), encoding="utf-8")))
    assert [r["name"] for r in rows] == ["sand", "pile 2"] and list(rows[0]) == list(COLUMNS)
    assert float(rows[0]["volume_m3"]) == pytest.approx(inv.piles[0].volume_m3, abs=1e-3)
    assert rows[1]["tonnes"] == "" and rows[0]["warnings"] == ""
    report = json.loads(json.dumps({"piles": report_piles(inv)}))
    first = report["piles"][0]
    assert first["base"] == "triangulated" and first["interval_m3"][0] < first["volume_m3"] < first["interval_m3"][1]
    assert set(first["by_base_m3"]) == {"triangulated", "plane", "lowest", "average", "highest"}
    assert first["tonnes_interval"][0] == pytest.approx(first["interval_m3"][0] * 1.6, abs=0.01)


def test_polygons_read_back_from_a_vector_file(two_piles, tmp_path):
    survey, inv = two_piles
    path = write_gpkg(tmp_path / "piles.gpkg", inv, survey.grid)
    piles, wkt = read_piles(path, density_field="density_t_m3")
    assert [(p.name, p.density) for p in piles] == [("sand", 1.6), ("pile 2", None)]
    local = local_piles(piles, wkt, survey.grid)
    assert local[0].polygon.symmetric_difference(inv.piles[0].polygon).area < 1e-6
    again = stockpile_inventory(survey, local)
    # the same within 0.1 %: the toe points of a round toe are nearly on a circle, and the rounding
    # of the coordinates moved to UTM and back may turn one of their Delaunay triangles' diagonals
    assert [p.volume_m3 for p in again.piles] == pytest.approx([p.volume_m3 for p in inv.piles], rel=1e-3)


def _write(path, polygons, densities):
    raw.write(
        str(path),
        geometry=shapely.to_wkb(polygons),
        field_data=[np.array(["a", "b"], dtype=object), np.array(densities, dtype=np.float64)],
        fields=["name", "density"],
        driver="GPKG",
        geometry_type="Polygon",
        crs=CRS,
    )


@pytest.mark.parametrize(
    "polygons, densities, words",
    [
        ([shapely.box(0, 0, 5, 5), shapely.Polygon([(0, 0), (5, 5), (5, 0), (0, 5)])], [1.5, 1.5], "'b': the polygon"),
        ([shapely.box(0, 0, 5, 5), shapely.box(9, 9, 12, 12)], [1.5, 0.0], "'b': density must be above 0"),
    ],
)
def test_a_bad_feature_is_refused_naming_the_file(tmp_path, polygons, densities, words):
    path = tmp_path / "toes.gpkg"
    _write(path, polygons, densities)
    before = path.read_bytes()
    with pytest.raises(PileError) as exc:
        read_piles(path, density_field="density")
    text = str(exc.value)
    assert "\n" not in text and str(path) in text and words in text
    assert path.read_bytes() == before


def test_missing_file_and_field(tmp_path):
    with pytest.raises(PileError, match="not found"):
        read_piles(tmp_path / "none.gpkg")
    path = tmp_path / "toes.gpkg"
    _write(path, [shapely.box(0, 0, 5, 5), shapely.box(9, 9, 12, 12)], [1.5, 2.0])
    with pytest.raises(PileError, match="no field 'tonnage'"):
        read_piles(path, density_field="tonnage")
