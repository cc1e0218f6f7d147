"""``soilvolume series ... --design DESIGN --tolerance T``: each epoch graded against a design and
each period's progress, on a seeded site whose surveys approach a design plane strip by strip
(exact: every cell's points on the design plus its strip's offset, symmetric about the cell's
centre, so each cell's height is the plane's at its centre plus the offset)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pyproj
import pytest
import rasterio
from affine import Affine
from designs import tin_of, write_landxml
from osgeo import ogr, osr

from soilvolume.api import series
from soilvolume.cli import main
from soilvolume.dem.geotiff import Layout, write_geotiff
from soilvolume.inputs.io import write_las
from soilvolume.options import Options

UTM = "EPSG:32654"
X0, Y0, W, H, STRIP = 500000.0, 3900000.0, 60.0, 40.0, 15.0
T = 0.05
#: survey - design per 15 m strip, epoch by epoch: the cut (> T) and the fill (< -T) done step by step
OFFSETS = (
    (0.40, -0.30, 0.20, -0.10),
    (0.25, -0.30, 0.02, -0.10),
    (0.10, -0.12, 0.00, 0.03),
    (0.00, 0.00, 0.00, -0.04),
)
OPTIONS = {"cell": 1.0, "georeferencing": "precise", "exclude": "none", "objects": "count"}


def plane(x, y):
    return 50.0 + 0.03 * (x - X0) - 0.02 * (y - Y0)


def strip_of(x):
    return np.clip(((np.asarray(x) - X0) // STRIP).astype(int), 0, 3)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """(folder, epoch paths, design.tif, zones.gpkg: the west and the east halves)."""
    folder = tmp_path_factory.mktemp("seriesdesign")
    g = np.arange(0.125, 1.0, 0.25)  # 4 x 4 points a cell, symmetric about its centre
    cx, cy = np.meshgrid(np.arange(W), np.arange(H))
    x = (cx.ravel()[:, None] + g[None, :].repeat(4, 0).ravel()).ravel() + X0
    y = (cy.ravel()[:, None] + g[:, None].repeat(4, 1).ravel()).ravel() + Y0
    wkt, paths = pyproj.CRS(UTM).to_wkt(), []
    for k, offsets in enumerate(OFFSETS):
        z = plane(x, y) + np.asarray(offsets)[strip_of(x)]
        paths.append(folder / f"e{k}.las")
        write_las(paths[-1], np.column_stack([x, y, z]), wkt, np.full(len(x), 2, np.uint8), scale=1e-6)
    t = Affine(0.5, 0, X0 - 10, 0, -0.5, Y0 + H + 10)
    xx, yy = np.meshgrid(t.c + 0.5 * (np.arange(160) + 0.5), t.f - 0.5 * (np.arange(120) + 0.5))
    design = write_geotiff(folder / "design.tif", [plane(xx, yy)], Layout(160, 120, t, UTM, "float64", float("nan")))
    zones = folder / "zones.gpkg"
    ds = ogr.GetDriverByName("GPKG").CreateDataSource(str(zones))
    srs = osr.SpatialReference()
    srs.ImportFromWkt(wkt)
    layer = ds.CreateLayer("zones", srs, ogr.wkbPolygon)
    layer.CreateField(ogr.FieldDefn("name", ogr.OFTString))
    for name, a, b in (("west", X0 - 5, X0 + 30), ("east", X0 + 30, X0 + W + 5)):
        f = ogr.Feature(layer.GetLayerDefn())
        f.SetField("name", name)
        box = f"POLYGON(({a} {Y0 - 5},{b} {Y0 - 5},{b} {Y0 + H + 5},{a} {Y0 + H + 5},{a} {Y0 - 5}))"
        f.SetGeometry(ogr.CreateGeometryFromWkt(box))
        layer.CreateFeature(f)
    ds = None
    return folder, paths, design, zones


@pytest.fixture(scope="module")
def run(site):
    folder, paths, design, zones = site
    out = folder / "out"
    report = series(paths, out, Options(**OPTIONS, design=str(design), tolerance=T, zones=str(zones))).report
    return out, report


def _to_go(offsets, cells: np.ndarray, where=slice(None)) -> tuple[float, float]:
    """(cut, fill) to go (m^3, 1 m cells) of one epoch over the strips' compared ``cells``."""
    off = np.asarray(offsets)[where]
    n = cells[where]
    return float((off * n)[off > T].sum()), float((-off * n)[off < -T].sum())


def test_each_epoch_to_go_and_each_period_progress_are_exact(run):
    out, report = run
    with rasterio.open(out / "grade_epoch0.tif") as ds:
        compared = ds.read(1) != 255
        x = ds.transform.c + ds.transform.a * (np.arange(ds.width) + 0.5)
    assert compared.sum() >= 0.95 * W * H
    cells = np.array([(compared & (strip_of(x) == s)[None, :]).sum() for s in range(4)], float)
    um = 1e-5 * cells.sum()  # 10 micrometres a cell (float32 heights at 50 m)
    to_go = [_to_go(o, cells) for o in OFFSETS]
    for k, (e, offsets) in enumerate(zip(report["epochs"], OFFSETS, strict=True)):
        g = e["grade"]
        assert (g["cut_to_go_m3"], g["fill_to_go_m3"]) == pytest.approx(to_go[k], abs=um)
        on = np.abs(np.asarray(offsets)) <= T
        assert g["on_grade_share"] == pytest.approx(cells[on].sum() / cells.sum(), abs=1e-12)
        west, east = g["zones"]
        assert (west["cut_to_go_m3"], west["fill_to_go_m3"]) == pytest.approx(
            _to_go(offsets, cells, slice(0, 2)), abs=um
        )
        assert (east["cut_to_go_m3"], east["fill_to_go_m3"]) == pytest.approx(
            _to_go(offsets, cells, slice(2, 4)), abs=um
        )
        with rasterio.open(out / f"grade_epoch{k}.tif") as ds:
            cls = ds.read(1)
        expected = np.where(np.asarray(offsets) > T, 1, np.where(np.asarray(offsets) < -T, 3, 2))[strip_of(x)]
        assert (cls[compared] == np.broadcast_to(expected, cls.shape)[compared]).all()
    changes = [*report["periods"], report["cumulative"]]
    for p in changes:
        done = p["progress"]
        i, j = p["from"], p["to"]
        assert done["cut_done_m3"] == pytest.approx(to_go[i][0] - to_go[j][0], abs=2 * um)
        assert done["fill_done_m3"] == pytest.approx(to_go[i][1] - to_go[j][1], abs=2 * um)
    n0, n1, n2, n3 = cells  # by hand: what each period did of the cut and fill to go
    by_hand = [(0.15 * n0 + 0.20 * n2, 0.0), (0.15 * n0, 0.18 * n1 + 0.10 * n3), (0.10 * n0, 0.12 * n1)]
    for p, (cut, fill) in zip(report["periods"], by_hand, strict=True):
        assert (p["progress"]["cut_done_m3"], p["progress"]["fill_done_m3"]) == pytest.approx((cut, fill), abs=2 * um)
    assert report["design"]["tolerance_m"] == T


def test_the_ledger_and_the_page_carry_the_progress(run):
    out, report = run
    with open(out / "ledger.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["period"] for r in rows] == ["1", "2", "3", "cumulative"]
    for r, p in zip(rows, [*report["periods"], report["cumulative"]], strict=True):
        for key in ("cut_done_m3", "fill_done_m3", "cut_to_go_m3", "fill_to_go_m3"):
            assert float(r[key]) == pytest.approx(p["progress"][key], abs=1e-3)
    assert json.loads((out / "report.json").read_text())["epochs"][3]["grade"]["on_grade_share"] == 1.0
    assert "Progress against the design" in (out / "report.html").read_text()


def test_a_landxml_design_grades_as_its_geotiff(site, run, tmp_path):
    folder, paths, design, _ = site
    xml = write_landxml(tmp_path / "design.xml", *tin_of(design), epsg=32654)
    report = series(paths, tmp_path / "out", Options(**OPTIONS, design=str(xml), tolerance=T)).report
    keys = ("compared_area_m2", "on_grade_share", "cut_to_go_m3", "fill_to_go_m3")
    for e, tif in zip(report["epochs"], run[1]["epochs"], strict=True):
        assert [e["grade"][k] for k in keys] == pytest.approx([tif["grade"][k] for k in keys], abs=1e-6 * W * H)
    assert "grade_epoch3.tif" in {p.name for p in (tmp_path / "out").iterdir()}


@pytest.mark.parametrize(
    ("case", "words"),
    [
        ("missing", "no such file"),
        ("elsewhere", "does not overlap"),
        ("no tolerance", "give --tolerance"),
        ("tolerance alone", "--tolerance: a series takes it with --design"),
        ("a cloud", "not a design surface"),
    ],
)
def test_a_bad_design_is_one_line_and_writes_nothing(site, tmp_path, capsys, case, words):
    folder, paths, design, _ = site
    far = tmp_path / "far.tif"
    t = Affine(0.5, 0, X0 + 5000, 0, -0.5, Y0 + 5000)
    write_geotiff(far, [np.full((20, 20), 50.0)], Layout(20, 20, t, UTM, "float64", float("nan")))
    given = {
        "missing": ["--design", str(tmp_path / "none.tif"), "--tolerance", "0.05"],
        "elsewhere": ["--design", str(far), "--tolerance", "0.05"],
        "no tolerance": ["--design", str(design)],
        "tolerance alone": ["--tolerance", "0.05"],
        "a cloud": ["--design", str(paths[2]), "--tolerance", "0.05"],
    }[case]
    before = [p.read_bytes() for p in paths]
    out = tmp_path / "out"
    flags = ["--cell", "1", "--georeferencing", "precise", "--quiet"]
    assert main(["series", *map(str, paths[:2]), "--out", str(out), *flags, *given]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert not out.exists() and [p.read_bytes() for p in paths] == before
