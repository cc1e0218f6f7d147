"""Tiled inputs: virtual point clouds (.vpc) and COPC files, read whole or within a box."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import laspy
import numpy as np
import pytest
from copc_writer import write_copc

from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs.io import write_las
from soilvolume.inputs.stream import open_source
from soilvolume.inputs.vpc import read_vpc, write_vpc

UTM = "EPSG:32654"


def _cloud(n: int = 40_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    xyz = np.c_[rng.uniform(500_000, 500_100, n), rng.uniform(4_000_000, 4_000_080, n), rng.uniform(10, 20, n)]
    return np.round(xyz, 3), rng.integers(1, 3, n).astype(np.uint8)


def _tiles(folder: Path, xyz: np.ndarray, cls: np.ndarray, crss=(UTM,) * 4) -> list[Path]:
    """Four quadrant tiles of the cloud, each in its CRS (coordinates unchanged)."""
    import pyproj

    cx, cy = 500_050, 4_000_040
    paths = []
    for k, (east, north) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        m = ((xyz[:, 0] >= cx) == bool(east)) & ((xyz[:, 1] >= cy) == bool(north))
        p = folder / f"tile_{k}.laz"
        write_las(p, xyz[m], pyproj.CRS(crss[k]).to_wkt(), cls[m])
        paths.append(p)
    return paths


def _read_all(src) -> np.ndarray:
    parts = [x for x, _ in src.chunks()]
    return np.concatenate(parts) if parts else np.empty((0, 3))


def _sorted(xyz: np.ndarray) -> np.ndarray:
    return xyz[np.lexsort(xyz.T[::-1])]


@pytest.mark.parametrize("relative", [True, False])
def test_vpc_hrefs_read_every_tile(tmp_path, relative):
    xyz, cls = _cloud()
    (tmp_path / "tiles").mkdir()
    tiles = _tiles(tmp_path / "tiles", xyz, cls)
    vpc = write_vpc(tmp_path / "survey.vpc", tiles, relative=relative)
    hrefs = [f["assets"]["data"]["href"] for f in json.loads(vpc.read_text())["features"]]
    assert all(h.startswith("tiles/") for h in hrefs) if relative else all(Path(h).is_absolute() for h in hrefs)
    src = open_source(vpc)
    assert src.count == len(xyz) and src.vpc is not None and "UTM zone 54N" in src.crs_wkt
    np.testing.assert_allclose(_sorted(_read_all(src)), _sorted(xyz), atol=1e-6)


def test_vpc_moved_with_relative_hrefs(tmp_path):
    """A folder with a VPC and relative hrefs can be moved as a whole."""
    xyz, cls = _cloud()
    (tmp_path / "a" / "tiles").mkdir(parents=True)
    tiles = _tiles(tmp_path / "a" / "tiles", xyz, cls)
    write_vpc(tmp_path / "a" / "survey.vpc", tiles)
    shutil.move(tmp_path / "a", tmp_path / "b")
    assert len(_read_all(open_source(tmp_path / "b" / "survey.vpc"))) == len(xyz)


def test_vpc_reads_only_tiles_meeting_the_box(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls)
    src = open_source(write_vpc(tmp_path / "s.vpc", tiles)).within((500_010, 4_000_010), (500_030, 4_000_030))
    assert [Path(t).name for t in src.tiles()] == ["tile_0.laz"]
    got = _read_all(src)
    assert len(got) == int(((xyz[:, 0] < 500_050) & (xyz[:, 1] < 4_000_040)).sum())


def test_vpc_mixed_crs_refused(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls, crss=(UTM, UTM, "EPSG:32655", UTM))
    with pytest.raises(SoilVolumeError, match=r"different CRSs.*tile_0.laz.*tile_2.laz"):
        read_vpc(write_vpc(tmp_path / "s.vpc", tiles))


def test_vpc_missing_tile_named(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls)
    vpc = write_vpc(tmp_path / "s.vpc", tiles)
    tiles[3].unlink()
    with pytest.raises(SoilVolumeError, match=r"s\.vpc: tile tile_3\.laz not found"):
        open_source(vpc)


def test_vpc_not_a_feature_collection(tmp_path):
    bad = tmp_path / "bad.vpc"
    bad.write_text('{"type": "Feature"}')
    with pytest.raises(SoilVolumeError, match="not a virtual point cloud"):
        open_source(bad)


def test_vpc_wgs84_bbox_when_no_proj_bbox(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls)
    vpc = write_vpc(tmp_path / "s.vpc", tiles)
    doc = json.loads(vpc.read_text())
    for f in doc["features"]:
        del f["properties"]["proj:bbox"]
    vpc.write_text(json.dumps(doc))
    src = open_source(vpc).within((500_010, 4_000_010), (500_030, 4_000_030))
    assert [Path(t).name for t in src.tiles()] == ["tile_0.laz"]


def test_copc_box_read_equals_full_read_filtered(tmp_path):
    import pyproj

    xyz, cls = _cloud(60_000)
    path = write_copc(tmp_path / "c.copc.laz", xyz, cls, pyproj.CRS(UTM).to_wkt())
    full = laspy.read(path)
    assert full.header.point_count == len(xyz)
    src = open_source(path)
    assert src.count == len(xyz) and src.crs_wkt
    np.testing.assert_allclose(_sorted(_read_all(src)), _sorted(xyz), atol=1e-6)
    lo, hi = np.array([500_020.0, 4_000_015.0]), np.array([500_045.0, 4_000_050.0])
    inside = ((xyz[:, :2] >= lo) & (xyz[:, :2] <= hi)).all(axis=1)
    got = _read_all(src.within(lo, hi))
    np.testing.assert_allclose(_sorted(got), _sorted(xyz[inside]), atol=1e-6)


def test_copc_tiles_in_a_vpc(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls)
    copcs = [write_copc(tmp_path / f"{t.stem}.copc.laz", laspy.read(t).xyz, seed=k) for k, t in enumerate(tiles)]
    src = open_source(write_vpc(tmp_path / "s.vpc", copcs)).within((500_010, 4_000_010), (500_030, 4_000_030))
    got = _read_all(src)
    inside = ((xyz[:, :2] >= (500_010, 4_000_010)) & (xyz[:, :2] <= (500_030, 4_000_030))).all(axis=1)
    np.testing.assert_allclose(_sorted(got), _sorted(xyz[inside]), atol=1e-6)


def test_indexed_las_reads_only_chunks_meeting_the_box(tmp_path):
    """A single LAS file streamed once records each chunk's box; later bounded reads seek to the
    chunks meeting the box (what the tile tasks do with plain files)."""
    from dataclasses import replace

    from soilvolume.inputs.stream import file_chunks

    xyz, cls = _cloud(30_000)
    order = np.argsort(xyz[:, 1])
    path = tmp_path / "strips.laz"
    write_las(path, xyz[order], None, cls[order])
    index, start = [], 0
    for part, _ in file_chunks(str(path), None, 5_000):
        index.append((start, len(part), part[:, :2].min(axis=0), part[:, :2].max(axis=0)))
        start += len(part)
    lo, hi = np.array([500_000.0, 4_000_020.0]), np.array([500_100.0, 4_000_030.0])
    src = replace(open_source(path), index=tuple(index)).within(lo, hi)
    got = np.concatenate([x for x, _ in src.chunks(5_000)])
    assert len(got) <= 10_000  # two or three of six chunks
    inside = ((xyz[:, :2] >= lo) & (xyz[:, :2] <= hi)).all(axis=1)
    sel = ((got[:, :2] >= lo) & (got[:, :2] <= hi)).all(axis=1)
    np.testing.assert_allclose(_sorted(got[sel]), _sorted(xyz[inside]), atol=1e-6)


def test_vpc_unreadable_tile_named(tmp_path):
    xyz, cls = _cloud()
    tiles = _tiles(tmp_path, xyz, cls)
    vpc = write_vpc(tmp_path / "s.vpc", tiles)
    tiles[1].write_bytes(b"LASF" + b"\0" * 50)  # truncated: the header says nothing sensible
    with pytest.raises(SoilVolumeError, match=r"tile_1\.laz: not a readable LAS/LAZ"):
        _read_all(open_source(vpc))


def test_copc_before_gives_the_las_result(tmp_path):
    """A COPC before cloud (read only where it meets the crop) gives the LAS result."""
    from conftest import write_scene

    from soilvolume.api import estimate
    from soilvolume.options import Options

    before, after, _ = write_scene(tmp_path / "pair", 5)
    las = laspy.read(before)
    copc = write_copc(
        tmp_path / "before.copc.laz",
        np.c_[las.x, las.y, las.z],
        np.asarray(las.classification),
        las.header.parse_crs().to_wkt(),
    )
    ref = estimate(before, after, tmp_path / "a", Options(scheduler="none"))
    got = estimate(copc, after, tmp_path / "b", Options(scheduler="none"))
    assert got.report["volume_m3"]["net"] == pytest.approx(ref.report["volume_m3"]["net"], rel=1e-3)


def test_copc_registration_pass_reads_a_thinning_level(tmp_path):
    """The first pass of a tiled run reads a COPC file only down to the octree level its
    registration columns need (here the root, 1/16 of the points) and scales the counts back:
    same totals, column centroids and counts close to a full read's."""
    import pyproj

    from soilvolume.distributed.scan import scan_unit
    from soilvolume.inputs.lasread import copc_chunks, read_fraction
    from soilvolume.inputs.stream import ColumnThinner
    from soilvolume.soil.points import PointRule

    xyz, cls = _cloud(80_000)
    path = write_copc(tmp_path / "c.copc.laz", xyz, cls, pyproj.CRS(UTM).to_wkt(), spacing=0.05)
    las = tmp_path / "c.laz"
    write_las(las, xyz, pyproj.CRS(UTM).to_wkt(), cls)
    voxel = 4.0  # columns of 4 m (resolution 1 m): the root level's 0.05 m spacing is enough
    assert read_fraction(path, resolution=1.0) == pytest.approx(1 / 16)
    assert sum(len(p) for p, _ in copc_chunks(path, resolution=1.0)) == len(xyz) // 16
    origin = np.array([500_000.0, 4_000_000.0, 0.0])
    lo, hi = np.zeros(3), np.array([100.0, 80.0, 0.0])
    args = (None, lambda p: p - origin, PointRule(), None, (lo, hi, voxel), False)
    thin = scan_unit((str(path), None, None), *args)
    full = scan_unit((str(las), 0, len(xyz)), *args)
    assert thin["points"] == full["points"] == len(xyz)
    n = ColumnThinner(lo, hi, voxel).sums.shape[1]
    for s in (thin, full):  # a task returns the sums of its columns with points: back to the grid's
        cols, vals = s["sums"]
        s["sums"] = np.zeros((4, n))
        s["sums"][:, cols] = vals
    n_thin, n_full = thin["sums"][3], full["sums"][3]
    assert n_thin.sum() == pytest.approx(n_full.sum())
    has = n_full > 0
    assert np.median(np.abs(n_thin[has] / n_full[has] - 1)) < 0.3  # ~12 of ~200 points per column
    centroids = [s["sums"][:3, has] / s["sums"][3, has] for s in (thin, full)]
    assert np.median(np.abs(centroids[0] - centroids[1])) < 1.0  # metres, in a 4 m column


def test_the_first_pass_adds_the_units_sums_in_their_order_however_tasks_finish():
    """Units' column sums arrive in any order (tasks finish when they finish); added in the units'
    order they give the same bits every run (floating-point addition is not associative)."""
    from itertools import permutations
    from types import SimpleNamespace

    from soilvolume.distributed.scan import _add_in_order

    parts = [(np.array([0]), np.array([[v]] * 4)) for v in (1e16, 1.0, -1e16, 1.0)]
    results = set()
    for order in permutations(range(len(parts))):
        thinner, waiting = SimpleNamespace(sums=np.zeros((4, 1))), {}
        for k, pos in enumerate(order, 1):
            waiting[pos] = parts[pos]
            _add_in_order(thinner, waiting, k - len(waiting))
        assert not waiting
        results.add(thinner.sums[0, 0])
    assert results == {1.0}  # ((1e16 + 1) - 1e16) + 1; in arrival order some orders give 0 or 2
