"""change_areas.gpkg, zones.gpkg and zones.csv: read back with pyogrio, in the run's CRS, their
attributes those of change_areas.geojson and report.json."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import shapely
from pyogrio import raw, read_info
from shapely.geometry import box

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.reporting.vectors import ZONE_COLUMNS


def _read(path, layer=None):
    meta, _fids, wkb, values = raw.read(str(path), layer=layer, return_fids=True)
    names = list(meta["fields"])
    rows = [dict(zip(names, [v[k] for v in values], strict=True)) for k in range(len(wkb))]
    return rows, shapely.from_wkb(wkb), meta


def test_change_areas_geopackage_only_when_asked(misaligned_result):
    """GeoPackage copies load pyogrio (its own GDAL, ~0.2 s): written with --gpkg only."""
    _res, _truth, out = misaligned_result
    assert (out / "change_areas.geojson").exists() and not (out / "change_areas.gpkg").exists()


def test_change_areas_geopackage_holds_the_geojson(tmp_path):
    from conftest import write_scene

    b, a, _truth = write_scene(tmp_path / "pair", seed=0)
    out = tmp_path / "out"
    estimate(b, a, out, Options(gpkg=True))
    doc = json.loads((out / "change_areas.geojson").read_text())
    rows, geoms, _meta = _read(out / "change_areas.gpkg")
    assert read_info(out / "change_areas.gpkg")["crs"] == "EPSG:32654"
    assert len(rows) == len(doc["features"]) > 0
    for row, geom, feat in zip(rows, geoms, doc["features"], strict=True):
        props = feat["properties"]
        assert {k: row[k] for k in props} == props
        assert geom.area == pytest.approx(props["area_m2"], abs=1e-3)
    head = json.loads((out / "report.json").read_text())["volume_m3"]
    for kind in ("cut", "fill"):
        mine = [r["volume_m3"] for r in rows if r["kind"] == kind]
        assert sum(mine) == pytest.approx(head[kind], abs=1e-3 * len(mine))


def _zones_file(path, polys, names):
    raw.write(
        str(path),
        geometry=shapely.to_wkb(polys),
        field_data=[np.array(list(names), dtype=object)],
        fields=["name"],
        driver="GeoJSON",
        geometry_type="Polygon",
        crs="EPSG:32654",
    )
    return path


def test_zones_geopackage_and_csv_equal_the_report(tmp_path):
    from conftest import write_scene

    b, a, _truth = write_scene(tmp_path / "pair", seed=0)
    west, east = box(500000, 3900000, 500081.5, 3900200), box(500081.5, 3900000, 500200, 3900200)
    zones = _zones_file(tmp_path / "zones.geojson", [west, east], ["west", "east"])
    out = tmp_path / "out"
    estimate(b, a, out, Options(zones=str(zones), gpkg=True))
    report = json.loads((out / "report.json").read_text())["zones"]
    rows, geoms, _meta = _read(out / "zones.gpkg")
    assert read_info(out / "zones.gpkg")["crs"] == "EPSG:32654"
    assert [r["name"] for r in rows] == ["west", "east"]
    assert [g.area for g in geoms] == pytest.approx([west.area, east.area])
    with open(out / "zones.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == list(ZONE_COLUMNS)
    for zone, row, line in zip(report, rows, table, strict=True):
        pm = zone["uncertainty_m3"]
        for part in ("net", "cut", "fill"):
            want = (zone[part], zone[part] - pm[part], zone[part] + pm[part])
            got = (row[f"{part}_m3"], row[f"{part}_low_m3"], row[f"{part}_high_m3"])
            assert got == want
            assert tuple(float(line[f"{part}{s}_m3"]) for s in ("", "_low", "_high")) == want
        assert row["area_m2"] == zone["area_m2"] == float(line["area_m2"])
        assert line["name"] == zone["name"] and int(line["id"]) == zone["id"]
        assert int(line["outside_grid"]) == zone["outside_grid"]


def test_no_zones_files_without_zones(misaligned_result):
    _res, _truth, out = misaligned_result
    assert not (out / "zones.gpkg").exists() and not (out / "zones.csv").exists()
