"""Earthworks quantities (issue 54, item 2): bank, loose and compacted volumes by the bulking and
shrinkage factors, overall and per zone (a zone's own factor from its polygon's attributes), on a
seeded survey against its design; numbers of a run without them unchanged."""

from __future__ import annotations

import json

import numpy as np
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


# --- progress against a design: --tolerance on a seeded plane -------------------------------------
UTM = "EPSG:32654"
X0, Y0, W, H = 500000.0, 3900000.0, 60.0, 40.0
OFFSETS = (-0.2, 0.03, 0.3, -0.04)  # design - survey per 15 m strip: cut to go, on grade, fill to go, on grade


def plane(x, y):
    return 50.0 + 0.03 * (x - X0) - 0.02 * (y - Y0)


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """(folder, survey, design on the run's grid with a known offset per strip, that grid)."""
    import pyproj
    import rasterio
    from affine import Affine

    from soilvolume.dem.geotiff import Layout, write_geotiff
    from soilvolume.inputs.io import write_las

    folder = tmp_path_factory.mktemp("grade")
    rng = np.random.default_rng(54)
    xy = rng.uniform((X0, Y0), (X0 + W, Y0 + H), (int(W * H * 40), 2))
    xyz = np.column_stack([xy, plane(xy[:, 0], xy[:, 1])])
    survey = folder / "survey.las"
    write_las(survey, xyz, pyproj.CRS(UTM).to_wkt(), np.full(len(xyz), 2, np.uint8), scale=1e-6)

    def design_tif(path, transform, cols, rows, offsets):
        x = transform.c + transform.a * (np.arange(cols) + 0.5)
        y = transform.f + transform.e * (np.arange(rows) + 0.5)
        xx, yy = np.meshgrid(x, y)
        strip = np.clip(((xx - X0) // 15).astype(int), 0, 3)
        z = plane(xx, yy) + np.asarray(offsets)[strip]
        return write_geotiff(path, [z], Layout(cols, rows, transform, UTM, "float64", float("nan")))

    first = design_tif(folder / "first.tif", Affine(0.5, 0, X0 - 10, 0, -0.5, Y0 + H + 10), 160, 120, (0,) * 4)
    run = estimate(first, survey, folder / "first", Options(cell=1.0)).report
    with rasterio.open(folder / "first" / "difference.tif") as ds:
        t, (rows, cols) = ds.transform, ds.shape
    big = Affine(t.a, 0, t.c - 5 * t.a, 0, t.e, t.f - 5 * t.e)  # the run's grid, 5 cells wider
    design = design_tif(folder / "design.tif", big, cols + 10, rows + 10, OFFSETS)
    assert run["grid"]["cell_m"] == 1.0
    return folder, survey, design, (t, rows, cols)


def test_grade_classes_and_volumes_to_go_are_exact(graded, tmp_path):
    import rasterio

    folder, survey, design, (t, rows, cols) = graded
    zones = tmp_path / "zones.gpkg"
    report0 = {"grid": {"transform": list(t)[:6], "rows": rows, "cols": cols, "crs_wkt": _wkt()}}
    write_zones(zones, report0, [{}, {}])  # west and east halves
    out = tmp_path / "out"
    report = estimate(design, survey, out, Options(cell=1.0, tolerance=0.05, zones=str(zones))).report
    with rasterio.open(out / "grade.tif") as ds, rasterio.open(out / "difference.tif") as dd:
        cls, diff, gt = ds.read(1), dd.read(1, masked=True), ds.transform
        assert ds.dtypes[0] == "uint8" and ds.nodata == 255 and gt == t
    x = gt.c + gt.a * (np.arange(cols) + 0.5)
    strip = np.clip(((x - X0) // 15).astype(int), 0, 3)
    expected = np.broadcast_to(np.array([1, 2, 3, 2])[strip], cls.shape)
    compared = ~np.ma.getmaskarray(diff)
    assert compared.sum() > 0.95 * rows * cols
    assert (cls[compared] == expected[compared]).all() and (cls[~compared] == 255).all()
    g, area = report["grade"], t.a * -t.e
    n = [int((compared & (expected == k)).sum()) for k in (1, 2, 3)]
    um = 1e-5 * area  # exact to 10 micrometres a cell (the run's heights are float32 at 50 m: ~4 um)
    assert g["cut_to_go_m3"] == pytest.approx(0.2 * n[0] * area, abs=um * n[0])
    assert g["fill_to_go_m3"] == pytest.approx(0.3 * n[2] * area, abs=um * n[2])
    assert g["on_grade_share"] == pytest.approx(n[1] / sum(n), abs=1e-12)
    west, east = g["zones"]
    assert west["cut_to_go_m3"] == pytest.approx(g["cut_to_go_m3"], rel=1e-12) and west["fill_to_go_m3"] == 0
    assert east["fill_to_go_m3"] == pytest.approx(g["fill_to_go_m3"], rel=1e-12) and east["cut_to_go_m3"] == 0
    assert "Progress against the design" in (out / "report.html").read_text()


def _wkt():
    import pyproj

    return pyproj.CRS(UTM).to_wkt()


def test_a_tolerance_needs_a_design(plain, tmp_path):
    folder, design, after, _ = plain
    before = folder / "before.laz" if (folder / "before.laz").exists() else next(folder.glob("before*"))
    _refused(
        tmp_path, before, after, "--tolerance: an on-grade tolerance needs a design as BEFORE", "--tolerance", "0.05"
    )
    _refused(tmp_path, design, after, "--tolerance: must be a finite number > 0", "--tolerance", "0")


def test_a_series_gives_each_period_its_quantities(tmp_path):
    from soilvolume.api import series
    from soilvolume.scenes.series import write_series

    paths, _ = write_series(tmp_path / "scene", seed=0)
    report = series(paths[:3], tmp_path / "out", Options(bulking=1.3, shrinkage=0.85)).report
    for p in [*report["periods"], report["cumulative"]]:
        q = p["quantities"]
        _scaled(q["bank"], p["volume_m3"], p["uncertainty_m3"], 1.0)
        _scaled(q["loose"], p["volume_m3"], p["uncertainty_m3"], 1.3)
        _scaled(q["compacted"], p["volume_m3"], p["uncertainty_m3"], 0.85)
    assert json.loads((tmp_path / "out" / "report.json").read_text())["options"]["bulking"] == 1.3
