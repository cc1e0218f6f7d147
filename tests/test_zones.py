"""Per-zone budgets from polygon files (GeoJSON in lon/lat, GeoPackage in the grid CRS)."""

from __future__ import annotations

import json

import numpy as np
import pyproj
import pytest

from soilvolume.core.types import GridSpec, SoilVolumeError
from soilvolume.volumes.change import budget
from soilvolume.volumes.zones import polygons_mask, zone_budgets

UTM = pyproj.CRS.from_epsg(32654)
GRID = GridSpec(
    xmin=500000.0, ymax=3900100.0, cell=0.5, rows=200, cols=200, origin=(500000.0, 3900000.0, 0.0), crs_wkt=UTM.to_wkt()
)


def diff() -> np.ndarray:
    rng = np.random.default_rng(3)
    d = rng.normal(0, 0.3, (GRID.rows, GRID.cols))
    d[:5] = np.nan
    return d


def box(x0, y0, x1, y1):
    return [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]


def write_geojson_lonlat(path, boxes, names):
    tr = pyproj.Transformer.from_crs(UTM, "EPSG:4326", always_xy=True)
    feats = [
        {
            "type": "Feature",
            "properties": {"name": n},
            "geometry": {"type": "Polygon", "coordinates": [[list(tr.transform(x, y)) for x, y in ring] for ring in b]},
        }
        for b, n in zip(boxes, names, strict=True)
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))


def test_zone_sums_equal_totals_after_reprojection(tmp_path):
    path = tmp_path / "zones.geojson"
    write_geojson_lonlat(
        path, [box(499990, 3899990, 500050, 3900110), box(500050, 3899990, 500110, 3900110)], ["west", "east"]
    )
    d = diff()
    zones = zone_budgets(d, GRID, path)
    total = budget(d, GRID.cell_area, np.ones(d.shape, bool))
    assert [z["name"] for z in zones] == ["west", "east"]
    for key in ("net", "cut", "fill", "area_m2"):
        assert sum(z[key] for z in zones) == pytest.approx(total[key], rel=1e-9, abs=1e-9)
    assert zones[0]["zone_area_m2"] == pytest.approx(5000.0)
    west = budget(d[:, :100], GRID.cell_area, np.ones((200, 100), bool))
    assert zones[0]["net"] == pytest.approx(west["net"])


def test_geopackage_in_grid_crs_with_name_field_and_mask(tmp_path):
    from osgeo import ogr, osr

    path = tmp_path / "stable.gpkg"
    ds = ogr.GetDriverByName("GPKG").CreateDataSource(str(path))
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32654)
    layer = ds.CreateLayer("zones", srs, ogr.wkbPolygon)
    layer.CreateField(ogr.FieldDefn("zone_id", ogr.OFTString))
    f = ogr.Feature(layer.GetLayerDefn())
    f.SetField("zone_id", "pad A")
    f.SetGeometry(
        ogr.CreateGeometryFromJson(
            json.dumps({"type": "Polygon", "coordinates": box(500010, 3900010, 500020, 3900030)})
        )
    )
    layer.CreateFeature(f)
    ds = None
    zones = zone_budgets(diff(), GRID, path, name_field="zone_id")
    assert zones[0]["name"] == "pad A" and zones[0]["zone_area_m2"] == pytest.approx(200.0)
    assert polygons_mask(path, GRID).sum() == 800
    with pytest.raises(SoilVolumeError, match="no field 'nope'"):
        zone_budgets(diff(), GRID, path, name_field="nope")


def test_unreadable_file_names_it(tmp_path):
    bad = tmp_path / "broken.gpkg"
    bad.write_text("not a geopackage")
    with pytest.raises(SoilVolumeError, match="broken.gpkg"):
        zone_budgets(diff(), GRID, bad)
    with pytest.raises(SoilVolumeError, match="missing.shp"):
        zone_budgets(diff(), GRID, tmp_path / "missing.shp")


def _geojson(path, rings, crs="EPSG:32654", names=None):
    feats = [
        {"type": "Feature", "properties": {"name": n}, "geometry": {"type": "Polygon", "coordinates": r}}
        for r, n in zip(rings, names or [f"z{k}" for k in range(len(rings))], strict=True)
    ]
    doc = {"type": "FeatureCollection", "features": feats}
    if crs:
        doc["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(doc))
    return path


def test_the_reader_gives_the_zones_and_their_crs(tmp_path):
    from soilvolume.volumes import polygons

    path = _geojson(tmp_path / "z.geojson", [box(500010, 3900010, 500020, 3900030)], names=["pad"])
    ((_, fid, props, geom), *rest), wkt = polygons._features(path, "zones file", "polygons", polygons.POLYGONAL)
    assert not rest and props["name"] == "pad" and geom.area == pytest.approx(200.0) and "UTM zone 54N" in wkt


def test_without_pyogrio_one_line_names_it(tmp_path, monkeypatch):
    import builtins

    from soilvolume.volumes import polygons

    real = builtins.__import__

    def block(name, *args, **kwargs):
        if name.split(".")[0] == "pyogrio":
            raise ImportError(f"No module named '{name}' (blocked by the test)", name=name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", block)
    path = _geojson(tmp_path / "z.geojson", [box(500010, 3900010, 500020, 3900030)], names=["pad"])
    with pytest.raises(SoilVolumeError, match="z.geojson: reading polygons needs pyogrio"):
        polygons.read_polygons(path)


def test_a_self_intersecting_zone_is_repaired_and_said(tmp_path):
    bowtie = [[[500010, 3900010], [500030, 3900030], [500030, 3900010], [500010, 3900030], [500010, 3900010]]]
    path = _geojson(tmp_path / "bowtie.geojson", [bowtie])
    (row,) = zone_budgets(diff(), GRID, path)
    assert row["repaired"] and row["polygon_area_m2"] == pytest.approx(200.0)  # two triangles
    assert row["zone_area_m2"] == pytest.approx(200.0, rel=0.1)
    from soilvolume.volumes.zones import zone_messages

    assert any("repaired" in m and "'z0'" in m for m in zone_messages([row]))


def test_zones_outside_the_grid_are_flagged_and_all_outside_refused(tmp_path):
    from soilvolume.volumes.zones import zone_messages

    inside, far = box(500010, 3900010, 500020, 3900030), box(510000, 3910000, 510010, 3910010)
    rows = zone_budgets(diff(), GRID, _geojson(tmp_path / "some.geojson", [inside, far], names=["in", "far"]))
    assert [r["outside_grid"] for r in rows] == [False, True] and rows[1]["net"] == 0.0
    assert any("'far'" in m and "not measured" in m for m in zone_messages(rows))
    with pytest.raises(SoilVolumeError, match=r"far\.geojson: no zone meets the survey's grid \(is its CRS right"):
        zone_budgets(diff(), GRID, _geojson(tmp_path / "far.geojson", [far]))


def test_a_zone_in_a_crs_that_cannot_hold_its_coordinates_is_refused(tmp_path):
    path = _geojson(tmp_path / "lonlat.geojson", [box(500010, 3900010, 500020, 3900030)], crs="EPSG:4326")
    with pytest.raises(SoilVolumeError, match=r"'z0' cannot be brought from WGS 84 into the survey's"):
        zone_budgets(diff(), GRID, path)


def test_a_missing_stable_mask_is_not_called_a_zones_file(tmp_path):
    with pytest.raises(SoilVolumeError, match=r"nowhere\.gpkg: --stable-mask file not found"):
        polygons_mask(tmp_path / "nowhere.gpkg", GRID)


def test_each_zone_has_the_headline_model_interval_holding_its_truth(tmp_path):
    """A seeded pair cut in two zones (pile A and the pit west, piles B and C east) and a zone
    over everything: each zone's 95 % interval (report.json) holds its exact volumes, the
    zones' nets add up to the headline, and the zone over everything has the headline's ±."""
    from conftest import write_scene

    from soilvolume.api import estimate
    from soilvolume.options import Options

    b, a, truth = write_scene(tmp_path / "pair", seed=0)
    ox, oy = 500000.0, 3900000.0
    west, east, whole = box(ox, oy, 500081.5, 3900200), box(500081.5, oy, 500200, 3900200), box(ox, oy, 500200, 3900200)
    zones = _geojson(tmp_path / "zones.geojson", [west, east, whole], names=["west", "east", "all"])
    report = estimate(b, a, tmp_path / "out", Options(zones=str(zones))).report
    on_disk = json.loads((tmp_path / "out" / "report.json").read_text())
    assert on_disk["zones"] == report["zones"]
    rows = {z["name"]: z for z in report["zones"]}
    feats = truth["features"]
    exact = {
        "west": [f["sign"] * f["volume"] for f in feats if f["x"] < 500081.5],
        "east": [f["sign"] * f["volume"] for f in feats if f["x"] >= 500081.5],
    }
    assert len(exact["west"]) == 2 and len(exact["east"]) == 2  # pile A + pit, piles B + C
    for name, vols in exact.items():
        z, pm = rows[name], rows[name]["uncertainty_m3"]
        want = {"net": sum(vols), "fill": sum(v for v in vols if v > 0), "cut": -sum(v for v in vols if v < 0)}
        for part in ("net", "cut", "fill"):
            assert 0.0 < pm[part] < 0.2 * max(abs(want["net"]), 1.0), (name, part, pm)
            assert abs(z[part] - want[part]) <= pm[part], (name, part, z[part], want[part], pm[part])
    assert rows["west"]["net"] + rows["east"]["net"] == pytest.approx(report["volume_m3"]["net"], rel=1e-9)
    for part in ("net", "cut", "fill"):  # the same model: over every change cell, the headline's ±
        assert rows["all"]["uncertainty_m3"][part] == pytest.approx(report["uncertainty_m3"][part], rel=1e-9)
