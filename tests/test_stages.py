"""Each embedded PDAL stage against hand-computed expectations on small clouds."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.core import polygons
from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs import smrf
from soilvolume.pipelines.stages import StageContext, execute, files, filters
from soilvolume.pipelines.stages.view import PointView

REAL = "/work/shared/data/real/autzen_bmx_2010.las"
FT = 0.304800609601219  # metres per US survey foot


def view(x, y, z=None, **dims) -> PointView:
    x = np.asarray(x, dtype=np.float64)
    arrays = {
        "X": x,
        "Y": np.asarray(y, dtype=np.float64),
        "Z": np.zeros_like(x) if z is None else np.asarray(z, dtype=np.float64),
    }
    arrays.update({k: np.asarray(v) for k, v in dims.items()})
    return PointView(arrays, None)


def ctx(stage: str) -> StageContext:
    return StageContext("test.json", stage)


def run(fn, v, **opts):
    return fn(v, opts, ctx("stage"))


# ----------------------------------------------------------------------------- crop
def test_crop_polygon_covers_boundary_and_excludes_holes():
    wkt = "POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (4 4, 6 4, 6 6, 4 6, 4 4))"
    x = [0, 10, 5, 5, 2, 4, 5, 11, -0.001, 7]
    y = [0, 5, 0, 5, 2, 5, 4, 5, 5, 10]
    # vertex, right edge, bottom edge, hole centre, inside, hole edge, hole edge, out, out, top
    kept = run(filters.crop, view(x, y), polygon=wkt)
    assert sorted(zip(kept.arrays["X"].tolist(), kept.arrays["Y"].tolist(), strict=True)) == sorted(
        [(0, 0), (10, 5), (5, 0), (2, 2), (4, 5), (5, 4), (7, 10)]
    )


def test_polygon_cover_matches_brute_force_on_random_points():
    from matplotlib.path import Path

    rng = np.random.default_rng(1)
    ang = np.sort(rng.uniform(0, 2 * np.pi, 40))
    rad = rng.uniform(3, 10, 40)
    ring = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    pts = rng.uniform(-11, 11, (20000, 2))
    got = polygons.covers([ring], pts[:, 0], pts[:, 1])
    want = Path(np.vstack([ring, ring[:1]])).contains_points(pts)
    assert (got != want).sum() == 0


def test_polygon_cover_of_a_wide_cloud_tests_only_the_polygons_box_and_agrees():
    """A wide survey cropped to a small footprint: the points outside the rings' box are out
    without being sorted; on the box's own lines (a vertex, an edge's ends, outside corners of
    the box) the answer is the one the whole test gives."""
    rng = np.random.default_rng(2)
    ring = np.array([[2.0, 1.0], [6.0, 2.0], [7.0, 5.0], [3.0, 6.0], [1.0, 3.0]])
    pts = np.vstack([rng.uniform(-40, 40, (50_000, 2)), ring, [[1, 1], [7, 6], [1, 6], [7, 1], [4, 6], [1, 3.5]]])
    pts = np.vstack([pts, rng.choice([1.0, 7.0], (200, 1)) * [1, 0] + rng.uniform(1, 6, (200, 1)) * [0, 1]])
    got = polygons.covers([ring], pts[:, 0], pts[:, 1])
    assert np.array_equal(got, polygons._covers([ring], pts[:, 0], pts[:, 1]))
    assert got[50_000:50_005].all() and not got[50_005:50_009].any()  # vertices in, box corners out
    assert 0 < got.sum() < 0.01 * len(pts)


def test_crop_multipolygon():
    mp = "MULTIPOLYGON(((0 0, 1 0, 1 1, 0 1, 0 0)), ((5 5, 6 5, 6 6, 5 6, 5 5)))"
    v = view([0.5, 5.5, 3], [0.5, 5.5, 3])
    assert run(filters.crop, v, polygon=mp).arrays["X"].tolist() == [0.5, 5.5]
    assert run(filters.crop, v, polygon=[mp]).arrays["X"].tolist() == [0.5, 5.5]  # a list of one


def test_crop_needs_one_wkt_polygon_and_says_the_other_forms_need_pdal():
    square = "POLYGON((0 0, 1 0, 1 1, 0 1, 0 0))"
    geojson = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}
    for opts in ({}, {"polygon": [square, square]}, {"polygon": geojson}):
        with pytest.raises(SoilVolumeError, match=r"^pipeline test.json: stage: needs one WKT 'polygon' .*need PDAL"):
            run(filters.crop, view([0], [0]), **opts)
    with pytest.raises(SoilVolumeError, match="expected WKT POLYGON"):
        run(filters.crop, view([0], [0]), polygon="POINT(0 0)")


# ----------------------------------------------------------------------------- range / assign
def test_range_takes_closed_ranges_and_says_the_other_forms_need_pdal():
    v = view([0, 1, 2], [0] * 3, [0, 10, 20])
    assert run(filters.filter_range, v, limits="Z[:10]").arrays["X"].tolist() == [0, 1]
    for text in ("Z[0;1]", "Z(0:10]", "Z![0:10]"):
        with pytest.raises(SoilVolumeError, match=r"needs PDAL \(without it only 'Dimension\[lo:hi\]'\)"):
            run(filters.filter_range, v, limits=text)


def test_range_or_within_dimension_and_across_dimensions():
    v = view([0, 1, 2, 3, 4], [0] * 5, [0, 10, 20, 30, 40], Classification=np.array([1, 2, 6, 2, 7], dtype=np.uint8))
    out = run(filters.filter_range, v, limits="Classification[1:2],Classification[6:6],Z[10:30]")
    assert out.arrays["X"].tolist() == [1, 2, 3]
    out = run(filters.filter_range, v, limits="z[10:]")  # names are case-insensitive
    assert out.arrays["X"].tolist() == [1, 2, 3, 4]
    with pytest.raises(SoilVolumeError, match="invalid dimension name 'Intensity'"):
        run(filters.filter_range, v, limits="Intensity[0:1]")


def test_assign_value():
    v = view([0, 1], [0, 0], Classification=np.array([2, 7], dtype=np.uint8))
    out = run(filters.assign, v, value="Classification = 0")
    assert out.arrays["Classification"].tolist() == [0, 0]
    fresh = run(filters.assign, view([0, 1], [0, 0]), value="Classification = 0")
    assert fresh.arrays["Classification"].dtype == np.uint8 and fresh.arrays["Classification"].tolist() == [0, 0]
    with pytest.raises(SoilVolumeError, match="needs PDAL"):
        run(filters.assign, v, value="Classification = 2 WHERE Z > 1")


# ----------------------------------------------------------------------------- reprojection
def test_reprojection_geographic_to_utm_known_point():
    v = view([15.0], [0.0], [7.0])
    v.srs_wkt = "EPSG:4326"
    out = run(filters.reproject, v, out_srs="EPSG:32633")
    assert out.arrays["X"][0] == pytest.approx(500000.0, abs=1e-6)
    assert out.arrays["Y"][0] == pytest.approx(0.0, abs=1e-6)
    assert out.arrays["Z"][0] == 7.0
    assert "32633" in out.srs_wkt or "UTM zone 33N" in out.srs_wkt


def test_reprojection_vertical_us_survey_feet_to_metres():
    v = view([194480.0, 194500.0], [259230.0, 259250.0], [100.0, 430.0])
    v.srs_wkt = "EPSG:2991+6360"
    out = run(filters.reproject, v, out_srs="EPSG:2991+5703")
    np.testing.assert_allclose(out.arrays["Z"], [100 * FT, 430 * FT], rtol=1e-12)
    np.testing.assert_allclose(out.arrays["X"], [194480.0, 194500.0], atol=1e-6)


def test_reprojection_real_autzen_file_header_srs():
    raw = execute([{"type": "readers.las", "filename": REAL}])
    out = execute(
        [{"type": "readers.las", "filename": REAL}, {"type": "filters.reprojection", "out_srs": "EPSG:2991+5703"}]
    )
    assert "ftUS" in raw.srs_wkt or "US survey foot" in raw.srs_wkt
    assert len(out) == len(raw) == 829
    np.testing.assert_allclose(out.arrays["Z"], raw.arrays["Z"] * FT, rtol=1e-12)
    np.testing.assert_allclose(out.arrays["X"], raw.arrays["X"], atol=1e-6)
    assert "NAVD88 height" in out.srs_wkt and "ftUS" not in out.srs_wkt


def test_reprojection_needs_a_source_srs():
    with pytest.raises(SoilVolumeError, match="no SRS"):
        run(filters.reproject, view([0], [0]), out_srs="EPSG:4326")


# ----------------------------------------------------------------------------- readers
def test_readers_text_header_forms(tmp_path):
    f = tmp_path / "a.csv"
    f.write_text("X,Y,Z,Classification\n1,2,3,2\n4,5,6,7\n")
    v = files.read_text(None, {"filename": str(f)}, ctx("readers.text"))
    assert v.arrays["Z"].tolist() == [3, 6] and v.arrays["Classification"].dtype == np.uint8
    g = tmp_path / "b.xyz"
    g.write_text("1 2 3\n\n4  5 6\n")
    v = files.read_text(None, {"filename": str(g), "header": "X Y Z"}, ctx("readers.text"))
    assert v.arrays["X"].tolist() == [1, 4]
    with pytest.raises(SoilVolumeError, match="does not name X, Y and Z"):
        files.read_text(None, {"filename": str(g)}, ctx("readers.text"))


def test_readers_las_and_default_srs(tmp_path):
    v = execute([{"type": "readers.las", "filename": REAL, "default_srs": "EPSG:2991+5703"}])
    assert "ftUS" in v.srs_wkt  # the file's own SRS wins over default_srs
    f = tmp_path / "a.xyz"
    f.write_text("1 2 3\n")
    t = execute([{"type": "readers.text", "filename": str(f), "header": "X Y Z", "default_srs": "EPSG:32633"}])
    assert "UTM zone 33N" in t.srs_wkt
    assert {"X", "Y", "Z", "Classification", "ReturnNumber"} <= set(v.arrays)
    assert v.arrays["X"].dtype == np.float64 and v.arrays["Classification"].dtype == np.uint8
    with pytest.raises(SoilVolumeError, match="file not found"):
        execute([{"type": "readers.las", "filename": "/nonexistent.las"}], "p.json")


def test_writers_las_round_trip(tmp_path):
    import laspy

    out = tmp_path / "o.laz"
    v = execute(
        [
            {"type": "readers.las", "filename": REAL},
            {"type": "writers.las", "filename": str(out), "scale_x": 0.001, "scale_y": 0.001, "scale_z": 0.001},
        ]
    )
    las = laspy.read(out)
    np.testing.assert_allclose(las.x, v.arrays["X"], atol=6e-4)
    np.testing.assert_array_equal(np.asarray(las.classification), v.arrays["Classification"])
    assert las.header.parse_crs() is not None


# ----------------------------------------------------------------------------- smrf
def _scene(seed=0):
    """A sloped, gently rolling ground with two boxes (3 m and 6 m high) and scattered trees."""
    rng = np.random.default_rng(seed)
    n = 60_000
    x, y = rng.uniform(0, 100, n), rng.uniform(0, 80, n)
    ground = 0.05 * x + 0.3 * np.sin(y / 9.0) + rng.normal(0, 0.02, n)
    z = ground.copy()
    obj = np.zeros(n, dtype=bool)
    for x0, x1, y0, y1, h in [(20, 32, 20, 30, 3.0), (60, 75, 45, 60, 6.0)]:
        box = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        z[box] += h
        obj |= box
    trees = rng.choice(np.flatnonzero(~obj), 3000, replace=False)
    z[trees] += rng.uniform(2, 12, trees.size)
    obj[trees] = True
    return x, y, z, obj


def test_smrf_separates_ground_from_boxes_and_vegetation():
    x, y, z, obj = _scene()
    v = view(x, y, z)
    out = run(filters.smrf, v)  # PDAL defaults: cell 1, slope .15, window 18, threshold .5
    cls = out.arrays["Classification"]
    assert set(np.unique(cls)) == {1, 2}
    assert (cls[~obj] == 2).mean() > 0.97  # ground kept
    assert (cls[obj] == 1).mean() > 0.97  # boxes and trees rejected


def test_smrf_classifies_last_and_single_returns_only():
    x, y, z, obj = _scene(1)
    cls0 = np.full(len(x), 7, dtype=np.uint8)
    rn = np.ones(len(x), dtype=np.uint8)
    nr = np.ones(len(x), dtype=np.uint8)
    nr[:100], rn[:100] = 2, 1  # first of two returns: not processed (PDAL's default 'last, only')
    nr[100:200], rn[100:200] = 2, 2  # last of two: processed
    v = view(x, y, z, Classification=cls0.copy(), ReturnNumber=rn, NumberOfReturns=nr)
    cls = run(filters.smrf, v).arrays["Classification"]
    np.testing.assert_array_equal(cls[:100], 7)
    assert set(np.unique(cls[100:])) == {1, 2}
    assert (cls[100:][~obj[100:]] == 2).mean() > 0.97


def test_morphology_matches_pdal_diamond():
    a = np.zeros((7, 7))
    a[3, 3] = 1
    d2 = smrf.morph(a, 2, "dilation")
    expect = (np.abs(np.arange(7)[:, None] - 3) + np.abs(np.arange(7)[None, :] - 3)) <= 2
    np.testing.assert_array_equal(d2 == 1, expect)
    np.testing.assert_array_equal(smrf.morph(d2, 2, "erosion"), a)
