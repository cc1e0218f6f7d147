"""Each embedded PDAL stage against hand-computed expectations on small clouds."""

from __future__ import annotations

import numpy as np
import pytest

from soilvolume.core.types import SoilVolumeError
from soilvolume.pipelines.stages import (
    StageContext,
    execute,
    gdalgrid,
    geometry,
    outlier,
    readers,
    reprojection,
    sampling,
    smrf,
)
from soilvolume.pipelines.stages import crop as crop_stage
from soilvolume.pipelines.stages import range as range_stage
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
def test_crop_bounds_edges_are_inside_and_outside_inverts():
    v = view([0, 1, 2, 2.0000001, 1, 1], [0, 1, 2, 1, -1e-9, 1])
    kept = run(crop_stage.crop, v, bounds="([0, 2], [0, 2])")
    assert kept.arrays["X"].tolist() == [0, 1, 2, 1]  # both corners on the edge kept
    out = run(crop_stage.crop, v, bounds="([0, 2], [0, 2])", outside=True)
    assert len(out) == 2 and len(out) + len(kept) == len(v)


def test_crop_bounds_3d_and_geojson_forms():
    v = view([1, 1, 1], [1, 1, 1], [0, 5, 10])
    assert run(crop_stage.crop, v, bounds="([0,2],[0,2],[4,6])").arrays["Z"].tolist() == [5]
    assert len(run(crop_stage.crop, v, bounds=[0, 0, 2, 2])) == 3
    assert len(run(crop_stage.crop, v, bounds={"minx": 0, "miny": 0, "maxx": 0.5, "maxy": 2})) == 0


def test_crop_polygon_covers_boundary_and_excludes_holes():
    wkt = "POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (4 4, 6 4, 6 6, 4 6, 4 4))"
    x = [0, 10, 5, 5, 2, 4, 5, 11, -0.001, 7]
    y = [0, 5, 0, 5, 2, 5, 4, 5, 5, 10]
    # vertex, right edge, bottom edge, hole centre, inside, hole edge, hole edge, out, out, top
    kept = run(crop_stage.crop, view(x, y), polygon=wkt)
    assert sorted(zip(kept.arrays["X"].tolist(), kept.arrays["Y"].tolist(), strict=True)) == sorted(
        [(0, 0), (10, 5), (5, 0), (2, 2), (4, 5), (5, 4), (7, 10)]
    )
    out = run(crop_stage.crop, view(x, y), polygon=wkt, outside=True)
    assert sorted(out.arrays["X"].tolist()) == [-0.001, 5, 11]


def test_polygon_cover_matches_brute_force_on_random_points():
    from matplotlib.path import Path

    rng = np.random.default_rng(1)
    ang = np.sort(rng.uniform(0, 2 * np.pi, 40))
    rad = rng.uniform(3, 10, 40)
    ring = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    pts = rng.uniform(-11, 11, (20000, 2))
    got = geometry.covers([ring], pts[:, 0], pts[:, 1])
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
    got = geometry.covers([ring], pts[:, 0], pts[:, 1])
    assert np.array_equal(got, geometry._covers([ring], pts[:, 0], pts[:, 1]))
    assert got[50_000:50_005].all() and not got[50_005:50_009].any()  # vertices in, box corners out
    assert 0 < got.sum() < 0.01 * len(pts)


def test_crop_multipolygon_and_geojson_polygon():
    mp = "MULTIPOLYGON(((0 0, 1 0, 1 1, 0 1, 0 0)), ((5 5, 6 5, 6 6, 5 6, 5 5)))"
    v = view([0.5, 5.5, 3], [0.5, 5.5, 3])
    assert run(crop_stage.crop, v, polygon=mp).arrays["X"].tolist() == [0.5, 5.5]
    gj = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]]}
    assert run(crop_stage.crop, v, polygon=gj).arrays["X"].tolist() == [0.5]


def test_crop_point_distance_is_strict_circle_or_sphere():
    v = view([3, 2.999, 0, 0], [4, 4, 0, 0], [0, 0, 0, 5])
    kept = run(crop_stage.crop, v, point="POINT(0 0)", distance=5)
    assert kept.arrays["X"].tolist() == [2.999, 0, 0]  # (3,4) is at exactly 5: out
    kept3 = run(crop_stage.crop, v, point="POINT(0 0 0)", distance=5)
    assert kept3.arrays["Z"].tolist() == [0, 0]  # (0,0,5) at exactly 5 on the sphere: out


def test_crop_bounds_in_another_srs():
    v = view([500000.0, 400000.0], [0.0, 0.0])
    v.srs_wkt = "EPSG:32633"
    import pyproj

    v.srs_wkt = pyproj.CRS("EPSG:32633").to_wkt()
    kept = run(crop_stage.crop, v, bounds="([14.9, 15.1], [-0.1, 0.1])", a_srs="EPSG:4326")
    assert kept.arrays["X"].tolist() == [500000.0]


def test_crop_needs_one_region():
    with pytest.raises(SoilVolumeError, match="exactly one of"):
        run(crop_stage.crop, view([0], [0]))
    with pytest.raises(SoilVolumeError, match="several 'bounds' regions"):
        run(crop_stage.crop, view([0], [0]), bounds=["([0,1],[0,1])", "([2,3],[2,3])"])


# ----------------------------------------------------------------------------- outliers
def _brute_outliers(xyz, k, mult):
    d = np.sqrt(((xyz[:, None, :] - xyz[None, :, :]) ** 2).sum(-1))
    d.sort(axis=1)
    mean_d = d[:, 1 : k + 1].mean(axis=1)
    return mean_d >= mean_d.mean() + mult * mean_d.std(ddof=1)


def test_outlier_statistical_classifies_seven_and_matches_brute_force():
    rng = np.random.default_rng(0)
    gx, gy = np.meshgrid(np.arange(10.0), np.arange(10.0))
    pts = np.column_stack([gx.ravel(), gy.ravel(), rng.normal(0, 0.05, 100)])
    pts = np.vstack([pts, [[4.5, 4.5, 20.0], [30, 30, 0], [-12, 3, 1]]])
    v = view(*pts.T)
    out = run(outlier.outlier, v, method="statistical", mean_k=8, multiplier=2.0)
    assert len(out) == 103  # classified, not removed
    cls = out.arrays["Classification"]
    assert cls.dtype == np.uint8
    np.testing.assert_array_equal(cls == 7, _brute_outliers(pts, 8, 2.0))
    assert set(np.flatnonzero(cls == 7)) == {100, 101, 102}
    kept = run(range_stage.filter_range, out, limits="Classification![7:7]")
    assert len(kept) == 100


def test_outlier_statistical_hand_computed_line():
    # points at 0,1,2,3 and 10 on a line, k=1: mean NN distances 1,1,1,1,7;
    # mean 2.2, sample std sqrt(((1.2**2)*4 + 4.8**2)/4) = 2.683; threshold(m=1) 4.88 -> one outlier
    v = view([0, 1, 2, 3, 10], [0] * 5)
    out = run(outlier.outlier, v, mean_k=1, multiplier=1.0)
    assert out.arrays["Classification"].tolist() == [0, 0, 0, 0, 7]


def test_outlier_radius_method_and_all_outliers_leaves_view_unchanged():
    v = view([0, 0.5, 0.9, 5], [0, 0, 0, 0])
    out = run(outlier.outlier, v, method="radius", radius=1.0, min_k=2)
    # counts within r (self included): 3, 3, 3, 1 -> only the last has <= 2
    assert out.arrays["Classification"].tolist() == [0, 0, 0, 7]
    same = run(outlier.outlier, view([0, 10], [0, 0]), method="radius", radius=1.0, min_k=2)
    assert same.arrays["Classification"].tolist() == [0, 0]


# ----------------------------------------------------------------------------- range / assign
def test_range_syntax():
    r = range_stage.parse_ranges("Z[0:100],Classification![7:7], Red(20:40], Blue[:255)")
    assert [(x.name, x.lo, x.hi, x.lo_closed, x.hi_closed, x.negate) for x in r] == [
        ("Z", 0, 100, True, True, False),
        ("Classification", 7, 7, True, True, True),
        ("Red", 20, 40, False, True, False),
        ("Blue", None, 255, True, False, False),
    ]
    with pytest.raises(SoilVolumeError):
        range_stage.parse_ranges("Z[0;1]")


def test_range_or_within_dimension_and_across_dimensions():
    v = view([0, 1, 2, 3, 4], [0] * 5, [0, 10, 20, 30, 40], Classification=np.array([1, 2, 6, 2, 7], dtype=np.uint8))
    out = run(range_stage.filter_range, v, limits="Classification[1:2],Classification[6:6],Z(0:30]")
    assert out.arrays["X"].tolist() == [1, 2, 3]
    out = run(range_stage.filter_range, v, limits="z[10:]")  # names are case-insensitive
    assert out.arrays["X"].tolist() == [1, 2, 3, 4]
    with pytest.raises(SoilVolumeError, match="invalid dimension name 'Intensity'"):
        run(range_stage.filter_range, v, limits="Intensity[0:1]")


def test_assign_value_and_assignment():
    v = view([0, 1], [0, 0], Classification=np.array([2, 7], dtype=np.uint8))
    out = run(range_stage.assign, v, value="Classification = 0")
    assert out.arrays["Classification"].tolist() == [0, 0]
    out = run(range_stage.assign, view([0, 1], [0, 0], [1, 5]), assignment="Z[2:]=3")
    assert out.arrays["Z"].tolist() == [1, 3]
    with pytest.raises(SoilVolumeError, match="not supported"):
        run(range_stage.assign, v, value="Classification = 2 WHERE Z > 1")


# ----------------------------------------------------------------------------- thinning
def test_voxel_center_nearest_neighbor_keeps_point_nearest_each_centre():
    # cell 1 from the minimum corner (0,0,0): voxel (0,0,0) centre (.5,.5,.5), voxel x=1 centre 1.5
    x = [0.0, 0.45, 0.9, 1.2, 1.55, 1.9]
    y = [0.0, 0.5, 0.9, 0.0, 0.45, 0.9]
    z = [0.0, 0.55, 0.9, 0.0, 0.5, 0.9]
    out = run(sampling.voxel_center_nn, view(x, y, z), cell=1.0)
    assert out.arrays["X"].tolist() == [0.45, 1.55]


def test_voxel_thinning_one_point_per_voxel():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 10, (5000, 3))
    out = run(sampling.voxel_center_nn, view(*pts.T), cell=2.0)
    idx = np.floor((out.xyz - pts.min(axis=0)) / 2.0).astype(int)
    occupied = np.unique(np.floor((pts - pts.min(axis=0)) / 2.0).astype(int), axis=0)
    assert len(out) == len(occupied) == len(np.unique(idx, axis=0))


def test_sample_dart_throwing_keeps_points_at_least_radius_apart():
    x = np.arange(0, 2.5, 0.3)  # 0, .3, ..., 2.4
    out = run(sampling.sample, view(x, np.zeros_like(x)), radius=1.0)
    np.testing.assert_allclose(out.arrays["X"], [0.0, 1.2, 2.4])
    exact = run(sampling.sample, view([0.0, 1.0, 2.0], [0, 0, 0]), radius=1.0)
    assert len(exact) == 3  # exactly at the radius is allowed
    cell = run(sampling.sample, view(x, np.zeros_like(x)), cell=2 / np.sqrt(3))
    np.testing.assert_allclose(cell.arrays["X"], [0.0, 1.2, 2.4])
    with pytest.raises(SoilVolumeError, match="exactly one"):
        run(sampling.sample, view(x, x), radius=1.0, cell=1.0)


# ----------------------------------------------------------------------------- reprojection
def test_reprojection_geographic_to_utm_known_point():
    v = view([15.0], [0.0], [7.0])
    v.srs_wkt = None
    out = run(reprojection.reproject, v, in_srs="EPSG:4326", out_srs="EPSG:32633")
    assert out.arrays["X"][0] == pytest.approx(500000.0, abs=1e-6)
    assert out.arrays["Y"][0] == pytest.approx(0.0, abs=1e-6)
    assert out.arrays["Z"][0] == 7.0
    assert "32633" in out.srs_wkt or "UTM zone 33N" in out.srs_wkt


def test_reprojection_vertical_us_survey_feet_to_metres():
    v = view([194480.0, 194500.0], [259230.0, 259250.0], [100.0, 430.0])
    out = run(reprojection.reproject, v, in_srs="EPSG:2991+6360", out_srs="EPSG:2991+5703")
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
        run(reprojection.reproject, view([0], [0]), out_srs="EPSG:4326")


# ----------------------------------------------------------------------------- writers.gdal
def test_gdal_binmode_mean_count_min_max_equal_numpy(tmp_path):
    import rasterio

    rng = np.random.default_rng(5)
    x, y = rng.uniform(100, 110, 3000), rng.uniform(200, 205, 3000)
    z = rng.normal(50, 2, 3000)
    x[:5], y[:5] = 109.5, 204.5  # the same spot several times
    grid = gdalgrid.grid_from_bounds(x.min(), y.min(), x.max(), y.max(), 1.0)
    assert (grid.width, grid.height) == (int((x.max() - x.min()) // 1) + 1, int((y.max() - y.min()) // 1) + 1)
    out = gdalgrid.compute(grid, x, y, z, stats=("mean", "count", "min", "max"), binmode=True)
    i = np.floor(x - grid.x0).astype(int)
    j = np.floor(y - grid.y0).astype(int)
    row = grid.height - 1 - j  # row 0 is the top
    for r, c in {(a, b) for a, b in zip(row, i, strict=True)}:
        sel = (row == r) & (i == c)
        assert out["mean"][r, c] == pytest.approx(z[sel].mean(), abs=1e-9)
        assert out["count"][r, c] == sel.sum()
        assert out["min"][r, c] == z[sel].min() and out["max"][r, c] == z[sel].max()
    assert out["count"].sum() == 3000
    # through the writer: GeoTIFF geometry, band order, nodata
    v = view(x, y, z)
    execute_opts = {
        "type": "writers.gdal",
        "filename": str(tmp_path / "dem.tif"),
        "resolution": 1.0,
        "binmode": True,
        "output_type": "mean,count",
    }
    from soilvolume.pipelines.stages import writers

    writers.write_gdal(v, execute_opts, ctx("writers.gdal"))
    with rasterio.open(tmp_path / "dem.tif") as ds:
        assert ds.count == 2 and ds.descriptions == ("mean", "count")
        assert ds.transform.c == pytest.approx(x.min())
        assert ds.transform.f == pytest.approx(y.min() + grid.height)
        assert ds.nodata == -9999
        np.testing.assert_allclose(ds.read(1), np.where(np.isnan(out["mean"]), -9999, out["mean"]))


def test_gdal_origin_width_height_and_empty_cells():
    grid = gdalgrid.Grid(0.0, 0.0, 3, 2, 1.0)
    out = gdalgrid.compute(
        grid,
        np.array([0.5, 2.5, 5.0]),
        np.array([1.5, 0.5, 0.5]),
        np.array([10.0, 20.0, 99.0]),
        stats=("mean", "count"),
        binmode=True,
    )
    np.testing.assert_array_equal(out["count"], [[1, 0, 0], [0, 0, 1]])  # (5, .5) is off-grid
    assert out["mean"][0, 0] == 10 and out["mean"][1, 2] == 20 and np.isnan(out["mean"][0, 1])


def test_gdal_radius_mode_uses_cells_within_radius():
    grid = gdalgrid.Grid(0.0, 0.0, 5, 5, 1.0)
    # a point at the centre of cell (2, 2): default radius sqrt(2) (strict) reaches the 4
    # edge neighbours (distance 1) but not the diagonals (distance sqrt(2))
    out = gdalgrid.compute(grid, np.array([2.5]), np.array([2.5]), np.array([7.0]), stats=("count", "mean", "idw"))
    expect = np.zeros((5, 5))
    expect[2, 2] = expect[1, 2] = expect[3, 2] = expect[2, 1] = expect[2, 3] = 1
    np.testing.assert_array_equal(out["count"], expect)
    assert out["idw"][2, 2] == 7.0
    wide = gdalgrid.compute(grid, np.array([2.5]), np.array([2.5]), np.array([7.0]), stats=("count",), radius=1.5)
    assert wide["count"].sum() == 9


def test_gdal_window_fill_inverse_distance():
    grid = gdalgrid.Grid(0.0, 0.0, 3, 1, 1.0)
    out = gdalgrid.compute(
        grid,
        np.array([0.5, 2.5]),
        np.array([0.5, 0.5]),
        np.array([10.0, 40.0]),
        stats=("mean", "count"),
        binmode=True,
        window_size=1,
    )
    assert out["mean"][0, 1] == pytest.approx(25.0) and out["count"][0, 1] == 0


# ----------------------------------------------------------------------------- readers
def test_readers_text_header_forms(tmp_path):
    f = tmp_path / "a.csv"
    f.write_text("X,Y,Z,Classification\n1,2,3,2\n4,5,6,7\n")
    v = readers.read_text(None, {"filename": str(f)}, ctx("readers.text"))
    assert v.arrays["Z"].tolist() == [3, 6] and v.arrays["Classification"].dtype == np.uint8
    g = tmp_path / "b.xyz"
    g.write_text("1 2 3\n\n4  5 6\n")
    v = readers.read_text(None, {"filename": str(g), "header": "X Y Z"}, ctx("readers.text"))
    assert v.arrays["X"].tolist() == [1, 4]
    with pytest.raises(SoilVolumeError, match="does not name X, Y and Z"):
        readers.read_text(None, {"filename": str(g)}, ctx("readers.text"))


def test_readers_las_and_srs_options():
    v = execute([{"type": "readers.las", "filename": REAL, "override_srs": "EPSG:2991+5703"}])
    assert "ftUS" not in v.srs_wkt
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
    out = run(smrf.smrf, v)  # PDAL defaults: cell 1, slope .15, window 18, threshold .5
    cls = out.arrays["Classification"]
    assert set(np.unique(cls)) == {1, 2}
    assert (cls[~obj] == 2).mean() > 0.97  # ground kept
    assert (cls[obj] == 1).mean() > 0.97  # boxes and trees rejected


def test_smrf_ignore_and_returns_leave_other_points_alone():
    x, y, z, obj = _scene(1)
    cls0 = np.where(obj, 7, 0).astype(np.uint8)
    rn = np.ones(len(x), dtype=np.uint8)
    nr = np.ones(len(x), dtype=np.uint8)
    nr[:100], rn[:100] = 2, 1  # first of two returns: not processed by default
    v = view(x, y, z, Classification=cls0.copy(), ReturnNumber=rn, NumberOfReturns=nr)
    out = run(smrf.smrf, v, ignore="Classification[7:7]")
    cls = out.arrays["Classification"]
    np.testing.assert_array_equal(cls[obj], 7)
    np.testing.assert_array_equal(cls[:100], cls0[:100])
    assert (cls[100:][~obj[100:]] == 2).mean() > 0.97


def test_morphology_matches_pdal_diamond():
    a = np.zeros((7, 7))
    a[3, 3] = 1
    d2 = smrf.dilate(a, 2)
    expect = (np.abs(np.arange(7)[:, None] - 3) + np.abs(np.arange(7)[None, :] - 3)) <= 2
    np.testing.assert_array_equal(d2 == 1, expect)
    np.testing.assert_array_equal(smrf.erode(d2, 2), a)
