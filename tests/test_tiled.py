"""The distributed engine: tiles on a real Dask LocalCluster (2 worker processes), on a cluster
by address and on threads give the in-process result: bit for bit where the registration is the
same (tiles and the whole grid quantise heights on one lattice), to rounding where it is not (a
VPC's registration subset summed in another order: 99 % of cell values within 1 mm, all within
1 cm, volumes within 1e-3 relative)."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from conftest import write_scene

from soilvolume.api import estimate
from soilvolume.core.types import GridSpec, SoilVolumeError
from soilvolume.distributed.schedule import Schedule, choose, parse
from soilvolume.distributed.tiletask import tiles
from soilvolume.inputs.vpc import write_vpc
from soilvolume.options import Options

RASTERS = ("dem_before", "dem_after", "difference", "plane_offset", "filled_mask")


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("tiled_pair"), 3)


@pytest.fixture(scope="module")
def in_process(pair, tmp_path_factory):
    before, after, _ = pair
    return estimate(before, after, tmp_path_factory.mktemp("ip") / "r", Options(scheduler="none"))


def _same(got, ref, rel=1e-4):
    """``got`` (tiled) against ``ref`` (in one process): volumes within ``rel`` and rasters within
    1 cm (1 mm on 99 % of cells); ``rel`` 0: the same numbers and the same rasters, bit for bit
    (the same registration: tiles and the whole grid quantise heights on one lattice)."""
    for key in ("volume_m3", "volume_uncompensated_m3", "volume_change_areas_m3"):
        for part in ("net", "cut", "fill"):
            want = ref.report[key][part] if rel == 0 else pytest.approx(ref.report[key][part], rel=rel, abs=0.05)
            assert got.report[key][part] == want, (key, part)
        assert got.report[key]["cells"] == ref.report[key]["cells"]
    assert got.report["grid"]["transform"] == ref.report["grid"]["transform"]
    net = ref.report["uncertainty_m3"]["net"]
    assert got.report["uncertainty_m3"]["net"] == (net if rel == 0 else pytest.approx(net, rel=1e-3))
    for name in RASTERS:
        with rasterio.open(got.outputs[name]) as g, rasterio.open(ref.outputs[name]) as r:
            a, b = g.read(1, masked=True), r.read(1, masked=True)
            np.testing.assert_array_equal(a.mask, b.mask)
            err = np.abs(a.compressed().astype(float) - b.compressed())
            assert err.max() <= (0.0 if rel == 0 else 0.01) and np.mean(err <= 1e-3) >= 0.99, (name, err.max())


def test_local_cluster_two_processes_matches_in_process(pair, in_process, tmp_path):
    before, after, _ = pair
    got = estimate(before, after, tmp_path / "r", Options(scheduler="local:2", tile_cells=16))
    assert got.report["engine"]["scheduler"] == "local:2" and got.report["engine"]["tiles"] > 4
    _same(got, in_process, rel=0)
    with rasterio.open(got.outputs["difference"]) as ds:  # a COG: tiled, compressed
        assert ds.profile["tiled"] and ds.profile["compress"] == "deflate"
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"


def _quadrant_vpc(before, folder) -> tuple:
    """(the before cloud split into four quadrant LAZ tiles grouped by a VPC, the tiles)."""
    import laspy

    from soilvolume.inputs.io import write_las

    las = laspy.read(before)
    xyz, cls = np.c_[las.x, las.y, las.z], np.asarray(las.classification)
    mid = np.median(xyz[:, :2], axis=0)
    parts = []
    for k, (east, north) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        m = ((xyz[:, 0] >= mid[0]) == bool(east)) & ((xyz[:, 1] >= mid[1]) == bool(north))
        parts.append(folder / f"before_{k}.laz")
        write_las(parts[-1], xyz[m], las.header.parse_crs().to_wkt(), cls[m])
    return write_vpc(folder / "before.vpc", parts), parts


def test_vpc_tiles_on_threads_match_single_file(pair, in_process, tmp_path):
    before, after, _ = pair
    vpc, _ = _quadrant_vpc(before, tmp_path)
    got = estimate(vpc, after, tmp_path / "r", Options(scheduler="threads:2", tile_cells=20))
    # the registration subset is summed in another order: the transform moves by float rounding
    _same(got, in_process, rel=1e-3)


def test_schedule_parsing_and_auto():
    assert parse("local:3") == Schedule("local", 3)
    assert parse("threads:1") == Schedule("threads", 1)
    assert parse("tcp://10.0.0.1:8786") == Schedule("tcp", address="tcp://10.0.0.1:8786")
    assert parse("none") == Schedule("none") and parse("auto") is None
    for bad in ("local:0", "cluster", "threads:x"):
        with pytest.raises(SoilVolumeError, match="--scheduler"):
            parse(bad)
    assert choose(4.0, 4_000_000).kind == "none"
    assert choose(1.0, 64_000_000).kind == "local"


def test_tiles_cover_the_grid_once():
    g = GridSpec(0.0, 100.0, 1.0, 37, 53)
    cover = np.zeros((g.rows, g.cols), int)
    for r0, r1, c0, c1 in tiles(g, 16):
        cover[r0:r1, c0:c1] += 1
    assert (cover == 1).all()


def test_tiles_aligned_to_the_input_tiling():
    g = GridSpec(500_012.5, 4_000_101.0, 0.5, 126, 134)  # 50 m data tiles = 100 cells
    edges = sorted({c0 for _, _, c0, _ in tiles(g, 100, 50.0)})
    assert [round(g.xmin + c * g.cell, 3) % 50 for c in edges[1:]] == [0.0]


def test_the_data_tiling_comes_from_the_tiles_corners_not_their_point_boxes():
    """A 50 m tiling whose header boxes span 49.999 m (the points, not the tiles) and whose corner
    tiles start inside their tile: pitch 50 m and the corner on the 50 m lattice; windows cut on it
    cross no data tile (a 49.999 m pitch drifted a window edge 42 m off the tile edges here)."""
    from types import SimpleNamespace

    from soilvolume.distributed.tiletask import data_tiling
    from soilvolume.inputs.vpc import Tile

    def tile(i, j, inset=0.0):
        x, y = 500_000.0 + 50 * i, 3_900_000.0 + 50 * j
        return Tile(f"t{i}_{j}.laz", 1000, (x + inset, y + inset, 0.0), (x + 49.999, y + 49.999, 1.0))

    src = SimpleNamespace(
        vpc=SimpleNamespace(tiles=[tile(i, j, 7.3 if i == j == 0 else 0.0) for i in range(3) for j in range(3)])
    )
    pitch, x0, y0 = data_tiling(src, 0.5, 200)
    assert pitch == 50.0 and x0 % 50 == 0.0 and y0 % 50 == 0.0
    g = GridSpec(500_048.0, 3_900_106.5, 0.5, 126, 135)
    wins = tiles(g, 100, pitch, (x0, y0))
    inner = sorted({round(g.xmin + c0 * g.cell, 3) for _, _, c0, _ in wins} - {g.xmin})
    assert inner == [500_100.0]  # the 4-cell sliver at 500 050 merged into its neighbour
    assert data_tiling(src, 0.5, 99) is None  # a data tile larger than a grid tile may be


def _plan_of_missing_inputs(folder):
    """A tile plan over a 40 x 40 grid of 1 m cells whose input files do not exist."""
    import pyproj

    from soilvolume.distributed.tiletask import Plan
    from soilvolume.inputs.crs import WorkFrame

    crs = pyproj.CRS("EPSG:32654")
    g = GridSpec(0.0, 40.0, 1.0, 40, 40)
    paths = (str(folder / "gone_b.las"), str(folder / "gone_a.las"))
    return Plan(
        *paths,
        crs.to_wkt(),
        crs.to_wkt(),
        WorkFrame(crs, 1.0),
        np.zeros(3),
        g,
        np.eye(4),
        (False, False),
        np.zeros((3, 2)),
        "mean",
    )


def test_resume_runs_only_the_missing_tiles(tmp_path):
    """Tiles saved by an interrupted run are reused; a missing one runs (here: fails naming the
    input, which does not exist)."""
    from dask.distributed import Client

    from soilvolume.api import Hooks
    from soilvolume.distributed.tilestore import TileStore
    from soilvolume.distributed.tiletask import TILE_ARRAYS, run_tiles

    plan = _plan_of_missing_inputs(tmp_path)
    g = plan.grid
    windows = tiles(g, 20)
    store = TileStore(str(tmp_path), tuple(windows), "k1")
    for k, (r0, r1, c0, c1) in enumerate(windows):
        shape = (r1 - r0, c1 - c0)
        arrays = [_tile_array(n, shape, k, np.ones(shape, np.int32)) for n in TILE_ARRAYS]
        store.save((r0, r1, c0, c1), dict(zip(TILE_ARRAYS, arrays, strict=True)))
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as c:
        after, _ = run_tiles(c, plan, Hooks(), store)
        h_a, n_a = after.heights, after.counts
        assert h_a[0, 0] == 0 and h_a[39, 39] == 3 and (n_a == 1).all()
        with pytest.raises(SoilVolumeError, match="gone_b.las: file not found"):  # tiles of another key
            run_tiles(c, plan, Hooks(), TileStore(str(tmp_path), tuple(windows), "k2"))
        (tmp_path / "k1_h_a_20_40_20_40.npy").unlink()
        with pytest.raises(SoilVolumeError, match="gone_b.las: file not found"):
            run_tiles(c, plan, Hooks(), store)


def test_existing_cluster_by_address(pair, in_process, tmp_path):
    """--scheduler tcp://HOST:PORT: an already running cluster (here in this process)."""
    from dask.distributed import LocalCluster

    before, after, _ = pair
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, protocol="tcp", dashboard_address=None
    ) as cluster:
        got = estimate(before, after, tmp_path / "r", Options(scheduler=cluster.scheduler_address, tile_cells=24))
    assert got.report["engine"]["scheduler"].startswith("tcp://")
    _same(got, in_process, rel=0)


def test_auto_inside_qgis_uses_threads(monkeypatch):
    """Inside QGIS ``sys.executable`` is QGIS: worker processes cannot be spawned from it."""
    import sys

    monkeypatch.setattr(sys, "executable", "/usr/bin/qgis")
    assert choose(1.0, 64_000_000).kind == "threads"


def test_auto_without_dask_runs_in_process(monkeypatch):
    """A large pair with ``auto`` and no dask.distributed installed: in-process, as before."""
    from soilvolume.distributed import schedule

    monkeypatch.setattr(schedule, "has_dask", lambda: False)
    assert schedule.choose(1.0, 64_000_000).kind == "none"
    monkeypatch.undo()
    assert schedule.has_dask() is True  # installed by make setup


def test_copc_inputs_thinned_for_registration_match_in_process(pair, in_process, tmp_path):
    """COPC inputs whose registration pass reads only the root level (1/16 of the points, about
    one per registration column of this sparse pair): the grid of the LAS run (cell size from the
    scaled counts) and its volumes within 2 % or a quarter of the thinned run's interval."""
    import laspy
    from copc_writer import write_copc

    before, after, _ = pair
    copcs = []
    for k, path in enumerate((before, after)):
        las = laspy.read(path)
        xyz = np.c_[las.x, las.y, las.z]
        crs = las.header.parse_crs().to_wkt()
        copcs.append(write_copc(tmp_path / f"{k}.copc.laz", xyz, np.asarray(las.classification), crs, spacing=0.01))
    got = estimate(*copcs, tmp_path / "r", Options(scheduler="threads:2", tile_cells=24))
    ref = in_process.report
    assert got.report["grid"]["cell_m"] == ref["grid"]["cell_m"]
    for part in ("net", "cut", "fill"):
        off = abs(got.report["volume_m3"][part] - ref["volume_m3"][part])
        assert off <= 0.02 * abs(ref["volume_m3"][part]) or off <= got.report["uncertainty_m3"][part] / 4, part


def test_volume_step_tiles_on_a_local_cluster(pair, in_process, tmp_path):
    """The volume step tile by tile on 2 worker processes, the correction found on an overview
    of 2 x 2 cells: volumes within 1 % of the
    in-process run (cut within 2 m3), half-widths 0.5-2x the in-process ones (each 16-cell tile
    finds its level of detection and error model in its own 48-cell window; wider, never much
    narrower), and the difference raster within 2 cm on 99 % of its cells: the overview's
    correction is the only difference (max 1.4 cm on this pair, 3.2 cm at a corner of seed 1's);
    what the tiles compute with their neighbours (the refilled difference the correction is
    subtracted from: centring slopes, refills, hole fills) is the in-process one to 1 mm."""
    before, after, _ = pair
    got = estimate(before, after, tmp_path / "r", Options(scheduler="local:2", tile_cells=16, volume_step="tiles"))
    ref = in_process.report
    assert got.report["engine"]["volume_step"].startswith("tiles, overview of")
    for part in ("net", "cut", "fill"):
        v, r = got.report["volume_m3"][part], ref["volume_m3"][part]
        assert v == pytest.approx(r, rel=0.01, abs=2.0), part
        u, ur = got.report["uncertainty_m3"][part], ref["uncertainty_m3"][part]
        assert 0.5 * ur <= u <= 2.0 * ur + 2.0, (part, u, ur)
        # what the change areas leave out at their edges: the tiles' rings summed (each tile's difference carries
        # the overview's correction, up to 1.4 cm off the whole grid's here), not the overview's coarse rings
        s, sr = got.report["uncertainty"]["skirt_m3"][part], ref["uncertainty"]["skirt_m3"][part]
        assert (s > 0) == (sr > 0.5) and s == pytest.approx(sr, abs=4.0), (part, s, sr)
    with rasterio.open(got.outputs["difference"]) as g, rasterio.open(in_process.outputs["difference"]) as r:
        assert g.profile["tiled"] and g.overviews(1) is not None
        a, b = g.read(1, masked=True), r.read(1, masked=True)
        np.testing.assert_array_equal(a.mask, b.mask)
        assert np.mean(np.abs(a - b).compressed() <= 0.02) >= 0.99
    offsets = [_read(v.outputs["plane_offset"]) for v in (got, in_process)]
    refilled = (a.astype(float) + offsets[0]) - (b.astype(float) + offsets[1])  # before the correction
    assert np.mean(np.abs(refilled.compressed()) <= 1e-3) >= 0.99, np.abs(refilled).max()
    np.testing.assert_array_equal(*(_read(v.outputs["filled_mask"]) for v in (got, in_process)))
    assert not list(tmp_path.glob(".*soilvolume-tiles*"))  # the tile store is gone after success


def _read(path) -> np.ma.MaskedArray:
    with rasterio.open(path) as ds:
        return ds.read(1, masked=True).astype(float)


def test_overview_pieces():
    from soilvolume.distributed import tiletask

    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 10):
        counts = rng.integers(1, 40, n)
        hist = tiletask.count_histogram(counts)
        assert tiletask.median_from_histogram(hist) == np.median(counts)
    grid = GridSpec(xmin=0.0, ymax=50.0, cell=1.0, rows=50, cols=45)
    h = rng.normal(size=(50, 45))
    h[rng.random(h.shape) < 0.2] = np.nan
    n = rng.integers(0, 9, h.shape)
    k = 4
    sums = tuple(np.zeros((13, 12)) for _ in range(3))
    for win in tiles(grid, 16):
        tiletask.add_blocks(
            sums, tiletask.block_sums(win, k, h[win[0] : win[1], win[2] : win[3]], n[win[0] : win[1], win[2] : win[3]])
        )
    pad = np.full((52, 48), np.nan)
    pad[:50, :45] = h
    blocks = pad.reshape(13, 4, 12, 4)
    np.testing.assert_allclose(sums[0], np.nansum(blocks, axis=(1, 3)))
    np.testing.assert_array_equal(sums[1], np.isfinite(blocks).sum(axis=(1, 3)))
    assert sums[2].sum() == n.sum()
    up = tiletask.to_cells(np.arange(12.0)[None, :].repeat(13, 0), k, (0, 50, 0, 45))
    assert up.shape == (50, 45) and np.all(np.diff(up[0]) >= 0)
    from soilvolume.distributed.volumetiles import halo

    assert (halo(1.0), halo(0.05)) == (16, 100)  # cells, and at least 5 m on fine grids


def test_tile_store_reads_any_window(tmp_path):
    from soilvolume.distributed.tilestore import TileStore

    grid = GridSpec(xmin=0.0, ymax=40.0, cell=1.0, rows=40, cols=33)
    full = np.arange(40 * 33, dtype=float).reshape(40, 33)
    wins = tuple(tiles(grid, 12))
    store = TileStore(str(tmp_path), wins)
    for w in wins:
        store.save(w, {"a": full[w[0] : w[1], w[2] : w[3]]})
    assert all(store.has(["a"], w) for w in wins) and not store.has(["b"], wins[0])
    np.testing.assert_array_equal(store.read("a", (5, 31, 3, 30)), full[5:31, 3:30])
    assert not list(tmp_path.glob(".*"))  # no temporary files left


def test_dense_data_tiles_are_not_snapped_to_past_the_memory_budget(pair, tmp_path):
    """Grid tiles snap to a VPC's data tiles (each read once) only when a data tile's points fit a
    task's memory; over a tight budget (between what the smallest tile and a data tile need) the
    tiles come from the budget instead; below the smallest tile's need the budget is refused."""
    import laspy

    from soilvolume.distributed.schedule import TILE_BYTES_PER_POINT
    from soilvolume.distributed.tiletask import MIN_TILE

    before, after, _ = pair
    vpc, parts = _quadrant_vpc(before, tmp_path)
    one = dict(scheduler="threads:1", volume_step="whole")  # one worker: tiles up to half the grid
    roomy = estimate(vpc, after, tmp_path / "a", Options(**one))
    cell, engine = roomy.report["grid"]["cell_m"], roomy.report["engine"]
    step = np.ptp([laspy.read(p).x.min() for p in parts])  # the quadrants' corners, west to east
    assert abs(engine["tile_cells"] - step / cell) <= 1  # snapped to the data tiles (corners on cells)
    cells = (MIN_TILE**2 + engine["tile_cells"] ** 2) / 2  # fits the smallest tile, not a data tile
    budget = 2 * cells * engine["points_per_cell"] * TILE_BYTES_PER_POINT / 2**30
    tight = estimate(vpc, after, tmp_path / "b", Options(**one, memory_limit=budget))
    assert MIN_TILE <= tight.report["engine"]["tile_cells"] < engine["tile_cells"]
    assert tight.report["volume_m3"]["net"] == pytest.approx(roomy.report["volume_m3"]["net"], rel=1e-3)
    with pytest.raises(SoilVolumeError, match=r"--memory-limit: .* cannot hold a tile of \d+ cells"):
        estimate(vpc, after, tmp_path / "c", Options(**one, memory_limit=budget / 10))
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_overview_factor_from_budget_and_size():
    from soilvolume.distributed import tiletask
    from soilvolume.distributed.tiletask import volume_factor

    small = GridSpec(xmin=0.0, ymax=0.0, cell=0.5, rows=1000, cols=1000)  # 1e6 cells: ~200 MB
    huge = GridSpec(xmin=0.0, ymax=0.0, cell=0.5, rows=20_000, cols=20_000)  # 4e8 cells
    assert volume_factor(Options(memory_limit=8.0), small) == 1  # auto: the whole grid fits
    assert volume_factor(Options(memory_limit=8.0, volume_step="tiles"), small) == 2
    assert volume_factor(Options(memory_limit=0.1, volume_step="whole"), small) == 1
    k = volume_factor(Options(memory_limit=8.0), huge)
    assert k > 1 and huge.rows * huge.cols / k**2 <= tiletask.MAX_CELLS
    assert tiletask.factor(huge, 8.0) <= k


def _tile_array(name: str, shape: tuple[int, int], k: int, counts: np.ndarray) -> np.ndarray:
    """A stored tile's array: after heights ``k``, the given counts, zeros elsewhere."""
    if name.startswith("n_"):
        return counts
    return np.full(shape, float(k)) if name == "h_a" else np.zeros(shape)


def test_tiled_volume_step_resumes_from_its_store(tmp_path):
    """With the volume step in tiles, finished grid tiles live in the store: a second run only
    grids the missing ones (here: fails naming the input, which does not exist), and the
    overview and median counts come from the stored tiles."""
    from dask.distributed import Client

    from soilvolume.api import Hooks
    from soilvolume.distributed.tilestore import TileStore
    from soilvolume.distributed.tiletask import TILE_ARRAYS
    from soilvolume.distributed.volumetiles import grid_tiles

    plan = _plan_of_missing_inputs(tmp_path)
    g = plan.grid
    store = TileStore(str(tmp_path), tuple(tiles(g, 20)), "k1")
    for k, w in enumerate(store.windows):
        shape = (w[1] - w[0], w[3] - w[2])
        counts = np.full(shape, 4 + k, np.int32)
        arrays = tuple(_tile_array(n, shape, k, counts) for n in TILE_ARRAYS)
        store.save(w, dict(zip(TILE_ARRAYS, arrays, strict=True)))
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as c:
        (after, before), medians, stats = grid_tiles(c, plan, store, 4, Hooks())
        assert stats["read"] == 0 and medians == (5.5, 5.5)  # counts 4..7, 400 cells each
        assert after.heights.shape == (10, 10) and after.heights[0, 0] == 0 and after.heights[9, 9] == 3
        assert after.counts[0, 0] == 16 * 4  # a 4 x 4 block of cells with 4 points
        (tmp_path / "k1_h_a_20_40_20_40.npy").unlink()
        with pytest.raises(SoilVolumeError, match="gone_b.las: file not found"):
            grid_tiles(c, plan, store, 4, Hooks())


def test_an_interrupted_tiled_run_says_where_its_tiles_are_kept(pair, tmp_path, monkeypatch):
    """Nothing in the output folder, the one line names the kept tiles (a resume), and the store
    holds them with the record of what they were computed from."""
    import json
    import signal

    from soilvolume.core.interrupt import Interrupted
    from soilvolume.distributed.tiletask import TILE_ARRAYS
    from soilvolume.execution import tiled

    def interrupted(c, plan, hooks, store, *_):
        w = store.windows[0]
        store.save(w, {n: np.zeros((w[1] - w[0], w[3] - w[2])) for n in TILE_ARRAYS})
        raise Interrupted(signal.SIGINT)

    monkeypatch.setattr(tiled, "run_tiles", interrupted)  # where the tiled backend calls it
    before, after, _ = pair
    with pytest.raises(Interrupted, match=r"kept in .*\.r\.soilvolume-tiles for the same command to resume") as err:
        estimate(before, after, tmp_path / "r", Options(scheduler="threads:1", volume_step="whole"))
    assert err.value.exit_code == 130 and not (tmp_path / "r").exists()
    kept = tmp_path / ".r.soilvolume-tiles"
    assert len(list(kept.glob("*_h_a_*.npy"))) == 1 and not (kept / "dask").exists()
    assert set(json.loads((kept / "store.json").read_text())) == {"code", "inputs", "options", "plan"}


def test_tiled_run_writes_the_registered_cloud_as_in_process(pair, tmp_path):
    """--registered-cloud in a tiled run: the after cloud moved by the same registration."""
    import laspy

    before, after, _ = pair
    runs = {
        s: estimate(before, after, tmp_path / s, Options(scheduler=s, keep_registered_cloud=True))
        for s in ("threads:2", "none")
    }
    tiled, whole = (laspy.read(runs[s].outputs["after_registered"]) for s in ("threads:2", "none"))
    assert len(tiled.points) == len(whole.points) == len(laspy.read(after).points)
    t = np.array(runs["threads:2"].report["registration"]["transform"])
    np.testing.assert_allclose(t, runs["none"].report["registration"]["transform"], atol=1e-6)
    assert np.abs(tiled.xyz - whole.xyz).max() <= 2e-3


def test_a_tile_takes_its_cells_points_as_the_whole_grid_assigns_them():
    """A tile task's cells (tiletask._window_cells: the window's bounds tested on the fractional
    coordinates) are those the whole grid's flat ids give (truncated coordinates, then the row
    and column inside the window): the same points, ids, heights and offsets, points on cell
    edges, on the window's and the grid's borders and outside them included."""
    from soilvolume.dem.grid import OffsetSums, cell_coords, flat_ids
    from soilvolume.distributed.gridtile import _window_cells

    rng = np.random.default_rng(7)
    grid = GridSpec(xmin=500_000.0, ymax=4_000_030.0, cell=0.5, rows=60, cols=50, origin=(500_010.0, 4_000_000.0, 0.0))
    xy = rng.uniform((-12, -2), (17, 32), (40_000, 2))
    xy[:5000] = np.round(xy[:5000] * 2) / 2  # on the cells' edges
    xyz = np.c_[xy, rng.normal(0, 1, len(xy))].astype(np.float32)
    for win in [(0, 60, 0, 50), (10, 37, 5, 21), (59, 60, 49, 50), (0, 1, 0, 50)]:
        col, row, ok = cell_coords(xyz, grid)  # the reference: whole-grid ids
        r, c = np.divmod(flat_ids(col[ok], row[ok], grid.cols), grid.cols)
        m = (r >= win[0]) & (r < win[1]) & (c >= win[2]) & (c < win[3])
        want = (r[m] - win[0]) * (win[3] - win[2]) + (c[m] - win[2])
        n = (win[1] - win[0]) * (win[3] - win[2])
        ref, got = OffsetSums(n), OffsetSums(n)
        ref.add(want, col[ok][m], row[ok][m])
        (ids, which), z = _window_cells(xyz, grid, win, got, keep_ids=True)
        assert np.array_equal(ids, want) and ids.dtype == np.int32 and len(ids) > 0
        assert np.array_equal(which, np.flatnonzero(ok)[m]) and np.array_equal(z, xyz[ok, 2][m])
        assert np.array_equal(got.sx, ref.sx) and np.array_equal(got.sy, ref.sy)


def test_a_cluster_still_starting_when_the_run_ends_is_shut_down_before_its_scratch_goes():
    """A run that ends (an error, a signal) while its cluster still starts waits for the start
    and shuts the cluster down before it returns: its workers would otherwise come up after the
    run, into the scratch space the run removed (a hidden store left beside the output)."""
    import threading
    import time

    from soilvolume.distributed import cluster

    closed = []

    class Part:
        def __init__(self, name: str) -> None:
            self.name = name

        def close(self, timeout=None) -> None:
            closed.append((self.name, threading.current_thread().name))

    def start() -> tuple:
        time.sleep(0.4)
        return Part("cluster"), Part("client")

    starting = cluster.Starting(start, "local:2", 10.0)
    t = time.perf_counter()
    starting.close()
    assert 0.3 < time.perf_counter() - t < 5.0
    assert [c[0] for c in closed] == ["client", "cluster"]
    assert {c[1] for c in closed} == {threading.current_thread().name}  # here, before close() returned


def test_a_grid_task_takes_soil_and_other_points_apart_as_a_mask_would():
    """A chunk whose soil points come first (as the native scan keeps a tile) is cut by slices
    (views, no copies), any other by a mask: the same points, labels and order either way."""
    from soilvolume.distributed.gridtile import _soil_apart

    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(1000, 3)).astype(np.float32)
    mixed = rng.choice(np.array([0, 0, 0, 1, 3], np.uint8), 1000)
    first = np.sort(mixed)  # soil (0) first, then the others in order
    for labels in (mixed, first, np.zeros(1000, np.uint8), np.full(1000, 3, np.uint8)):
        soil, other, other_labels = _soil_apart(xyz, labels)
        keep = labels == 0
        assert np.array_equal(soil, xyz[keep]) and np.array_equal(other, xyz[~keep])
        assert np.array_equal(other_labels, labels[~keep])
        sliced = np.shares_memory(soil, xyz) or np.shares_memory(other, xyz)
        assert sliced == (labels is not mixed)  # slices unless mixed


def test_the_driver_waiting_for_its_tasks_lets_the_ahead_imports_go():
    """While the driver waits for its tasks (``waiting.completed``) the ahead imports' gate is open (they
    would otherwise run after the wait, in the driver's own time) and shut again once the results are in."""
    import threading
    import time

    from dask.distributed import Client

    from soilvolume.distributed.waiting import completed
    from soilvolume.native import OFF_THE_GIL

    OFF_THE_GIL.clear()
    opened = threading.Event()
    watcher = threading.Thread(target=lambda: OFF_THE_GIL.wait(10) and opened.set(), daemon=True)
    watcher.start()
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as c:
        futures = [c.submit(time.sleep, 0.5, pure=False)]
        assert not OFF_THE_GIL.is_set()
        assert list(completed(c, futures, "sleeping")) == [None]
    watcher.join(10)
    assert opened.is_set() and not OFF_THE_GIL.is_set()
