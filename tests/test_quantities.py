"""Earthworks quantities (issue 54, item 2): bank, loose and compacted volumes by the bulking and
shrinkage factors, overall and per zone (a zone's own factor from its polygon's attributes), on a
seeded survey against its design; numbers of a run without them unchanged."""

from __future__ import annotations

import json

import pytest
from conftest import run_cli
from designs import write_surface
from osgeo import ogr, osr

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.synthetic import make_pair, write_pair

SEED = 3
CONFIG = SceneConfig(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), noise_m=0.03)


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """(folder, design, survey, report of the run without factors)."""
    folder = tmp_path_factory.mktemp("quantities")
    _, after, _ = write_pair(make_pair(SEED, CONFIG), folder)
    design = write_surface(folder / "design.tif", SEED, CONFIG)
    return folder, design, after, estimate(design, after, folder / "plain", Options()).report


def write_zones(path, report: dict, factors: list[dict]) -> None:
    """The grid cut into vertical strips, one per entry of ``factors`` (its attributes)."""
    t, rows, cols = report["grid"]["transform"], report["grid"]["rows"], report["grid"]["cols"]
    x0, y1, w = t[2], t[5], cols * t[0] / len(factors)
    y0 = y1 + rows * t[4]
    ds = ogr.GetDriverByName("GPKG").CreateDataSource(str(path))
    srs = osr.SpatialReference()
    srs.ImportFromWkt(report["grid"]["crs_wkt"])
    layer = ds.CreateLayer("zones", srs, ogr.wkbPolygon)
    for name, kind in (("name", ogr.OFTString), ("Bulking", ogr.OFTReal), ("shrinkage", ogr.OFTReal)):
        layer.CreateField(ogr.FieldDefn(name, kind))
    for k, attrs in enumerate(factors):
        f = ogr.Feature(layer.GetLayerDefn())
        f.SetField("name", f"strip {k}")
        for key, value in attrs.items():
            f.SetField(key, value)
        a, b = x0 + k * w, x0 + (k + 1) * w
        f.SetGeometry(ogr.CreateGeometryFromWkt(f"POLYGON(({a} {y0},{b} {y0},{b} {y1},{a} {y1},{a} {y0}))"))
        layer.CreateFeature(f)
    ds = None


def _scaled(got: dict, bank: dict, half: dict, factor: float) -> None:
    for k in ("net", "cut", "fill"):
        assert got[k] == bank[k] * factor
        assert got["interval_m3"][k] == half[k] * factor


def test_bank_loose_and_compacted_overall_and_per_zone(plain, tmp_path):
    folder, design, after, before = plain
    assert "quantities" not in before and "bulking" not in before["options"]  # a run without them: as before
    zones = tmp_path / "zones.gpkg"
    write_zones(zones, before, [{"Bulking": 1.4, "shrinkage": 0.8}, {}])
    options = Options(bulking=1.25, shrinkage=0.9, zones=str(zones))
    report = estimate(design, after, tmp_path / "out", options).report
    assert report["volume_m3"] == before["volume_m3"] and report["uncertainty_m3"] == before["uncertainty_m3"]
    q, bank, half = report["quantities"], report["volume_m3"], report["uncertainty_m3"]
    _scaled(q["bank"], bank, half, 1.0)
    _scaled(q["loose"], bank, half, 1.25)
    _scaled(q["compacted"], bank, half, 0.9)
    own, rest = report["zones"]
    _scaled(own["quantities"]["loose"], own, own["uncertainty_m3"], 1.4)  # the zone's own factors
    _scaled(own["quantities"]["compacted"], own, own["uncertainty_m3"], 0.8)
    _scaled(rest["quantities"]["loose"], rest, rest["uncertainty_m3"], 1.25)  # the run's
    assert min(abs(own["cut"]), abs(rest["fill"]), abs(bank["cut"])) > 1.0  # volumes to scale
    saved = json.loads((tmp_path / "out" / "report.json").read_text())
    assert saved["quantities"]["loose"]["factor"] == 1.25
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Earthworks quantities" in html and "loose" in html


def _refused(folder, design, after, expect, *extra):
    out = folder / "refused"
    p = run_cli("estimate", design, after, "--out", out, "--quiet", *extra)
    msg = p.stderr.strip()
    assert p.returncode != 0 and len(msg.splitlines()) == 1 and expect in msg, msg
    assert not out.exists()


def test_factors_of_zero_or_below_are_refused(plain, tmp_path):
    folder, design, after, before = plain
    _refused(tmp_path, design, after, "--bulking: must be a finite number > 0", "--bulking", "0")
    _refused(tmp_path, design, after, "--shrinkage: must be a finite number > 0", "--shrinkage", "-0.9")
    zones = tmp_path / "zones.gpkg"
    write_zones(zones, before, [{"Bulking": 0.0}])
    _refused(tmp_path, design, after, "field 'bulking' must be a number > 0 (got 0.0)", "--zones", zones)
