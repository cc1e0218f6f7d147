"""Streaming input: chunked reading equals reading whole, column thinning, the crop mask, and
errors raised in the read-ahead thread reaching the caller."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from soilvolume.core.polygons import covers
from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs import stream
from soilvolume.inputs.footprint import PolygonMask, footprint
from soilvolume.inputs.io import RawPoints, write_las
from soilvolume.inputs.stream import ColumnThinner, from_raw, load, open_source


@pytest.fixture
def cloud(tmp_path):
    rng = np.random.default_rng(0)
    n = 25_000
    xyz = np.c_[500_000 + rng.uniform(0, 60, n), 3_900_000 + rng.uniform(0, 40, n), 50 + rng.normal(0, 0.2, n)]
    cls = np.where(rng.random(n) < 0.8, 2, 5).astype(np.uint8)
    path = tmp_path / "c.las"
    write_las(path, xyz, pyproj.CRS("EPSG:32654").to_wkt(), classification=cls)
    return path, xyz, cls


def _load(src, origin, keep=None, box=None, mode="auto"):
    lo, hi = np.array([-1.0, -1.0]), np.array([70.0, 50.0])
    return load(src, lambda x: x - origin, mode, keep, ColumnThinner(lo, hi, 0.5), box=box)


def test_chunked_load_equals_whole_load(cloud, monkeypatch):
    path, xyz, cls = cloud
    origin = np.array([500_000.0, 3_900_000.0, 50.0])
    monkeypatch.setattr(stream, "CHUNK", 1_000)  # 25 chunks
    las = open_source(path)
    assert len(list(las.chunks())) == 25
    whole = from_raw(RawPoints(np.c_[xyz].round(3), cls, las.crs_wkt, str(path)))
    keep = PolygonMask(np.array([[5.0, 5.0], [55.0, 5.0], [30.0, 35.0]]))
    box = (np.array([0.0, 0.0]), np.array([40.0, 30.0]))
    a, b = _load(las, origin, keep, box), _load(whole, origin, keep, box)
    assert a.note == b.note == "class 2 (ground)"
    assert a.used == b.used == int((cls == 2).sum())
    assert a.extra["cropped"] == b.extra["cropped"] > 0
    assert a.xyz.dtype == np.float32 and np.allclose(a.xyz, b.xyz, atol=1e-4)
    assert np.allclose(a.thin, b.thin, atol=1e-9)
    assert (a.xyz[:, :2] <= box[1] + 1e-4).all()


def test_column_thinner_gives_column_means():
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 10, (5_000, 3))
    t = ColumnThinner(np.zeros(2), np.full(2, 10.0), 2.5)
    t.add(pts[:2_000])
    t.add(pts[2_000:])
    got = t.columns()[0]
    ids = (pts[:, 1] // 2.5).astype(int) * t.shape[1] + (pts[:, 0] // 2.5).astype(int)
    want = np.array([pts[ids == k].mean(axis=0) for k in np.unique(ids)])
    assert np.allclose(got, want)


def test_polygon_mask_matches_exact_test_away_from_edges():
    rng = np.random.default_rng(2)
    poly = footprint(rng.uniform(0, 50, (200, 2)), radius=5.0)
    pts = rng.uniform(-10, 60, (50_000, 2))
    fast, exact = PolygonMask(poly, resolution=0.5)(pts), covers([poly], pts[:, 0], pts[:, 1])
    assert (fast != exact).mean() < 0.02  # only cells on the boundary can differ


def test_truncated_las_is_reported(cloud, tmp_path):
    path, _, _ = cloud
    cut = tmp_path / "cut.las"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(SoilVolumeError, match="cut.las"):  # found in the header, before reading
        _load(open_source(cut), np.zeros(3))


def _coloured(tmp_path, n=6_000):
    """A LAS file with colour (some green points), several returns and no class 2."""
    import laspy

    rng = np.random.default_rng(3)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.offsets, header.scales = np.array([500_000.0, 3_900_000.0, 0.0]), np.full(3, 0.001)
    header.add_crs(pyproj.CRS("EPSG:32654"))
    las = laspy.LasData(header)
    las.x, las.y, las.z = 500_000 + rng.uniform(0, 60, n), 3_900_000 + rng.uniform(0, 40, n), rng.normal(50, 0.3, n)
    green = rng.random(n) < 0.3
    las.red = np.where(green, 20_000, 40_000).astype(np.uint16)
    las.green = np.where(green, 50_000, 38_000).astype(np.uint16)
    las.blue = np.where(green, 15_000, 36_000).astype(np.uint16)
    las.number_of_returns = np.where(rng.random(n) < 0.2, 2, 1).astype(np.uint8)
    las.return_number = np.where((las.number_of_returns == 2) & (rng.random(n) < 0.5), 1, las.number_of_returns)
    path = tmp_path / "coloured.las"
    las.write(str(path))
    return path


@pytest.mark.parametrize("classified", [True, False])
def test_narrowed_signals_and_fused_shift_change_nothing(cloud, tmp_path, monkeypatch, classified):
    """Reading only the signals the rule uses, with the origin subtracted in the decoding, loads
    bit for bit what reading every signal and shifting afterwards loads."""
    from soilvolume.inputs.crs import Shift
    from soilvolume.soil import points

    path = cloud[0] if classified else _coloured(tmp_path)
    origin = np.array([500_010.0, 3_900_010.0, 49.0])
    monkeypatch.setattr(stream, "CHUNK", 1_000)
    las = open_source(path)
    keep = PolygonMask(np.array([[-5.0, -5.0], [45.0, -5.0], [20.0, 25.0]]))

    def both() -> list:
        box = np.array([-11.0, -11.0]), np.array([60.0, 40.0])
        return [load(las, f, "auto", keep, ColumnThinner(*box, 0.5)) for f in (Shift(origin), lambda x: x - origin)]

    narrowed = both()
    every = {*points.RGB_DIMS, *points.RETURN_DIMS}
    monkeypatch.setattr(stream, "deciding_dims", lambda *a: every)
    monkeypatch.setattr(points.PointRule, "signal_dims", property(lambda self: every))
    full = both()
    assert narrowed[0].nonsoil is not None and len(narrowed[0].nonsoil.labels) > 100
    for a, b in ((narrowed[0], full[1]), (narrowed[1], full[1]), (full[0], full[1])):
        assert a.nonsoil.rule == b.nonsoil.rule and (a.points, a.used, a.extra["cropped"]) == (
            b.points,
            b.used,
            b.extra["cropped"],
        )
        for x, y in (
            (a.xyz, b.xyz),
            (a.thin, b.thin),
            (a.nonsoil.xyz, b.nonsoil.xyz),
            (a.nonsoil.labels, b.nonsoil.labels),
        ):
            assert x.dtype == y.dtype and np.array_equal(x, y)
    rule = narrowed[0].nonsoil.rule
    assert rule.use_class if classified else (rule.green is not None and rule.returns)


@pytest.mark.parametrize("kind", ["rectangle", "gaussian", "grid", "rotated-grid", "disc", "line-ends"])
def test_the_hull_is_qhulls_on_every_point(kind):
    """The footprint's hull (Qhull on the points not well inside the extremes' octagon) is Qhull's
    hull of all the points, vertex for vertex and in the same order: on column centroids (a grid,
    its edges full of collinear points), rotated and far from the origin, and on random clouds."""
    from scipy.spatial import ConvexHull

    from soilvolume.inputs import footprint as fp

    rng = np.random.default_rng(len(kind))
    for n in (50, 3_000, 120_000, 450_000):
        if kind == "rectangle":
            xy = rng.random((n, 2)) * [100.0, 60.0]
        elif kind == "gaussian":
            xy = rng.normal(size=(n, 2)) * [30.0, 10.0]
        elif kind in ("grid", "rotated-grid"):
            m = int(np.sqrt(n))
            xy = np.mgrid[0:m, 0:m].reshape(2, -1).T * 0.5 + 0.25
            if kind == "rotated-grid":
                a = rng.random() * np.pi
                xy = xy @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]).T + [512_000.0, 4_100_000.0]
        elif kind == "disc":
            a, r = rng.random(n) * 2 * np.pi, np.sqrt(rng.random(n)) * 40
            xy = np.c_[r * np.cos(a), r * np.sin(a)] + 1000.0
        else:  # a strip whose extremes in several directions are the same two points
            xy = np.c_[np.linspace(0, 100, n), rng.random(n) * 1e-3]
        pts = xy[:: max(1, len(xy) // 200_000)]
        assert np.array_equal(fp._hull(xy), pts[ConvexHull(pts).vertices])


def test_the_footprint_test_in_the_decoding_loads_what_the_consumer_loads(cloud, monkeypatch):
    """With a plain shift the chunks arrive local and the footprint test runs in the decoding;
    after any other conversion the consumer applies it. Both load the same points."""
    from soilvolume.inputs.crs import Shift

    origin = np.array([500_010.0, 3_900_010.0, 49.0])
    monkeypatch.setattr(stream, "CHUNK", 1_000)
    las = open_source(cloud[0])
    keep = PolygonMask(np.array([[-5.0, -5.0], [45.0, -5.0], [20.0, 25.0]]))
    box = np.array([-11.0, -11.0]), np.array([60.0, 40.0])
    fused = load(las, Shift(origin), "auto", keep, ColumnThinner(*box, 0.5))
    shifted = load(las, lambda x: x - origin, "auto", keep, ColumnThinner(*box, 0.5))
    assert 0 < fused.extra["cropped"] < fused.points
    assert fused.xyz.tobytes() == shifted.xyz.tobytes() and fused.thin.tobytes() == shifted.thin.tobytes()
