"""The first pass's VPC tiles kept on the workers for the grid pass (distributed/pointcache):
the same rasters and volumes, byte for byte, as a run that reads every tile again; tiles beyond
the memory budget are read again."""

from __future__ import annotations

import json

import laspy
import numpy as np
import pytest
from conftest import write_scene

from soilvolume.api import estimate
from soilvolume.distributed import pointcache
from soilvolume.distributed.scan import _first_rule
from soilvolume.distributed.schedule import budget_gb
from soilvolume.inputs.io import write_las
from soilvolume.inputs.vpc import write_vpc
from soilvolume.options import Options

RASTERS = ("dem_before", "dem_after", "difference", "plane_offset", "filled_mask", "excluded")


def _vpc(las_path, folder, name: str):
    """The cloud split into 3 x 3 LAZ tiles grouped by a VPC."""
    las = laspy.read(las_path)
    xyz, cls = np.c_[las.x, las.y, las.z], np.asarray(las.classification)
    edges = [np.quantile(xyz[:, k], [1 / 3, 2 / 3]) for k in (0, 1)]
    i, j = (np.searchsorted(edges[k], xyz[:, k]) for k in (0, 1))
    parts = []
    for a in range(3):
        for b in range(3):
            m = (i == a) & (j == b)
            parts.append(folder / f"{name}_{a}{b}.laz")
            write_las(parts[-1], xyz[m], las.header.parse_crs().to_wkt(), cls[m])
    return write_vpc(folder / f"{name}.vpc", parts)


@pytest.fixture(scope="module")
def vpcs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cache_pair")
    before, after, _ = write_scene(folder, 3)
    return _vpc(before, folder, "before"), _vpc(after, folder, "after")


def _run(vpcs, out, scheduler: str):
    res = estimate(*vpcs, out, Options(scheduler=scheduler, tile_cells=24, volume_step="whole"))
    return res, res.report["engine"]


def _identical(got, ref) -> None:
    for key in ("volume_m3", "volume_uncompensated_m3", "volume_change_areas_m3"):
        assert json.dumps(got.report[key]) == json.dumps(ref.report[key]), key
    # the interval differs in the last bits between two runs of the same engine (threaded sums)
    assert got.report["uncertainty_m3"]["net"] == pytest.approx(ref.report["uncertainty_m3"]["net"], rel=1e-9)
    for name in RASTERS:
        assert got.outputs[name].read_bytes() == ref.outputs[name].read_bytes(), name


def test_cached_tiles_give_the_rereading_run_byte_for_byte(vpcs, tmp_path, monkeypatch):
    cached, eng = _run(vpcs, tmp_path / "cached", "threads:2")
    assert eng["points_kept_in_memory"] > 0 and eng["task_points_from_memory"] == eng["task_points_read"] > 0
    monkeypatch.setattr(pointcache, "CACHE_SHARE", 0.0)  # nothing fits: every grid task reads its tiles
    reread, eng0 = _run(vpcs, tmp_path / "reread", "threads:2")
    assert eng0["points_kept_in_memory"] == eng0["task_points_from_memory"] == 0
    assert eng0["task_points_read"] == eng["task_points_read"]
    _identical(cached, reread)
    # a budget for part of the tiles: those read again, the others from memory, the same result
    need = eng["points_kept_in_memory"] * pointcache.CACHE_BYTES_PER_POINT / 2**30
    monkeypatch.setattr(pointcache, "CACHE_SHARE", 0.4 * need / budget_gb(0))
    part, eng1 = _run(vpcs, tmp_path / "part", "threads:2")
    assert 0 < eng1["points_kept_in_memory"] < eng["points_kept_in_memory"]
    assert 0 < eng1["task_points_from_memory"] < eng1["task_points_read"]
    _identical(part, reread)


def test_cached_tiles_on_worker_processes(vpcs, tmp_path):
    """On a LocalCluster the cached tiles stay on the worker that read them; grid tasks on the
    other worker get them from it: the same result as on threads."""
    threads, _ = _run(vpcs, tmp_path / "threads", "threads:2")
    local, eng = _run(vpcs, tmp_path / "local", "local:2")
    assert eng["task_points_from_memory"] == eng["task_points_read"] > 0
    _identical(local, threads)


def test_tiles_the_driver_read_while_the_cluster_started(vpcs, tmp_path, monkeypatch):
    """Tiles scanned by the driver before the workers are up, then handed to them for the grid,
    give the run on the workers alone byte for byte."""
    from soilvolume.distributed import cluster

    ref, _ = _run(vpcs, tmp_path / "ref", "threads:2")
    calls = {"n": 0}

    def starting(self) -> bool:  # the cluster "starts" during the first four tiles (asked once before them)
        calls["n"] += 1
        return calls["n"] > 5

    monkeypatch.setattr(cluster.Starting, "ready", starting)
    held = []
    hold = pointcache.PointCache.hold
    monkeypatch.setattr(pointcache.PointCache, "hold", lambda self, *a: (held.append(a[1]), hold(self, *a)))
    got, eng = _run(vpcs, tmp_path / "driver", "threads:2")
    assert len(held) == 4 and eng["task_points_from_memory"] == eng["task_points_read"] > 0
    _identical(got, ref)


def test_tiles_the_driver_read_go_out_before_the_registration(vpcs, tmp_path, monkeypatch):
    """The driver read every tile (the cluster came up after its last scan, before the reading
    ended): they go out to the workers at the end of the reading, beside the registration, not
    when the grid needs them; the result is the run on the workers alone, byte for byte."""
    from soilvolume.distributed import cluster
    from soilvolume.execution import tiled as prep_mod  # where the tiled backend calls prepare
    from soilvolume.workflow import steps

    ref, _ = _run(vpcs, tmp_path / "ref", "threads:2")
    read, events = {"done": False}, []
    reading = prep_mod.prepare

    def prepare(*a, **k):
        out = reading(*a, **k)
        read["done"] = True  # up from here: after every scan, before the reading's end
        return out

    monkeypatch.setattr(prep_mod, "prepare", prepare)
    monkeypatch.setattr(cluster.Starting, "ready", lambda self: read["done"])
    send_held = pointcache.PointCache.send_held
    monkeypatch.setattr(
        pointcache.PointCache, "send_held", lambda self: (events.append(("send", len(self.held))), send_held(self))
    )
    register = steps.register
    monkeypatch.setattr(steps, "register", lambda *a: (events.append(("register", 0)), register(*a))[1])
    got, eng = _run(vpcs, tmp_path / "driver", "threads:2")
    sent = [k for k, (what, n) in enumerate(events) if what == "send" and n]
    assert sent and sent[0] < events.index(("register", 0)), events
    assert eng["task_points_from_memory"] == eng["task_points_read"] > 0
    _identical(got, ref)


class _SlowClient:
    """A client whose scatter takes ``delay`` s per tile (or fails with ``error``)."""

    def __init__(self, delay: float, error: Exception | None = None) -> None:
        self.delay, self.error, self.threads = delay, error, set()

    def scatter(self, data, hash=True, direct=None):  # noqa: A002 - Dask's keywords
        import threading
        import time

        self.threads.add(threading.current_thread().name)
        time.sleep(self.delay * len(data))
        if self.error is not None:
            raise self.error
        return [("future", d.points) for d in data]


def _holding(client, paths):
    from types import SimpleNamespace

    cache = pointcache.PointCache(client, 1.0)
    src = SimpleNamespace(vpc=SimpleNamespace(tiles=[SimpleNamespace(path=p, count=10) for p in paths]))
    for p in paths:
        cache.hold(src, (p, None), pointcache.KeptTile(((np.zeros((10, 3), np.float32), None),), 10))
    return cache, src


def test_tiles_the_driver_holds_go_to_the_workers_while_it_goes_on():
    """The driver's held tiles are sent by a thread (~0.2 s for the paper pair, which the driver
    waited for before its next tasks and the registration); the grid's lookup waits for them."""
    import threading
    import time

    client = _SlowClient(0.3)
    cache, src = _holding(client, ["a.laz", "b.laz"])
    t = time.perf_counter()
    cache.send_held()
    assert time.perf_counter() - t < 0.1 and not cache.held
    src.tiles = lambda: ["a.laz", "b.laz", "c.laz"]
    assert set(cache.meeting(src, None)) == {"a.laz", "b.laz"}  # waited: both futures there
    assert cache.meeting(src, "a crop") == {}  # kept uncropped: not for a cropped epoch
    assert time.perf_counter() - t >= 0.6 and client.threads == {"soilvolume-send-tiles"}
    assert threading.current_thread().name not in client.threads


def test_a_failure_to_send_the_held_tiles_is_one_line_in_the_driver():
    from soilvolume.core.types import SoilVolumeError

    cache, src = _holding(_SlowClient(0.0, OSError("connection reset by peer")), ["a.laz"])
    cache.send_held()
    with pytest.raises(SoilVolumeError, match=r"^sending the tiles read here to the Dask workers failed \("):
        cache.sent()
    cache.sent()  # said once


def test_a_signal_while_the_held_tiles_are_sent_stops_the_wait():
    """A send that hangs (a cluster gone quiet) does not hold a Ctrl-C for the 120 s timeout."""
    import time

    from soilvolume.core import interrupt

    hang = 5.0
    cache, _ = _holding(_SlowClient(hang), ["a.laz"])
    cache.send_held()
    interrupt._pending.append(2)  # SIGINT recorded by the run's handler
    try:
        t = time.perf_counter()
        with pytest.raises(interrupt.Interrupted):
            cache.sent()
        assert time.perf_counter() - t < 0.5 * hang  # relative to the hang: a loaded machine is slow, not 5 s slow
    finally:
        interrupt._pending.clear()


def test_a_kept_tile_holds_the_points_its_crop_keeps_as_the_grid_would_make_them(tmp_path):
    """What a scan keeps of a tile (scan_keeping) is what a grid task makes of the file itself:
    the local float32 points inside the crop, in the file's order, with their labels; an
    epoch without a crop keeps every point. The scan's own summary is the plain scan's."""
    import pyproj

    from soilvolume.distributed.scan import scan_keeping, scan_unit
    from soilvolume.inputs.crs import Shift
    from soilvolume.inputs.footprint import PolygonMask
    from soilvolume.soil.points import PointRule

    rng = np.random.default_rng(4)
    origin = np.array([500_000.0, 4_000_000.0, 10.0])
    xyz = origin + np.c_[rng.uniform(0, 60, (30_000, 2)), rng.normal(0, 1, 30_000)]
    cls = rng.choice([1, 2], 30_000).astype(np.uint8)
    path = tmp_path / "t.laz"
    write_las(path, xyz, pyproj.CRS("EPSG:32654").to_wkt(), cls)
    xyz = laspy.read(path).xyz  # the stored (quantised) coordinates
    ring = np.array([[5.0, 5.0], [50.0, 8.0], [40.0, 55.0], [8.0, 45.0]])
    keep, rule = PolygonMask(ring), PointRule(use_class=True)
    thinning = (np.zeros(3), np.array([60.0, 60.0, 0.0]), 2.0)
    for crop in (keep, None):
        args = ((str(path), None, None), None, Shift(origin), rule, crop, thinning, False)
        part, kept = scan_keeping(*args, cached=pointcache.read_tile(str(path)))
        plain = scan_unit(*args)
        same = lambda d: {k: v for k, v in d.items() if k not in ("sums", "read_s")}  # noqa: E731
        assert same(part) == same(plain)
        assert _epoch_sums(part, thinning) == _epoch_sums(plain, thinning)
        local = xyz - origin
        inside = keep(local) if crop is not None else np.ones(len(xyz), bool)
        got = np.concatenate([c[0] for c in kept.chunks])
        assert got.dtype == np.float32 and kept.points == len(xyz) and 0 < len(got) <= len(xyz)
        assert np.array_equal(got, local[inside].astype(np.float32))
        labels = np.concatenate([c[1] for c in kept.chunks])
        assert np.array_equal(labels, rule.labels(cls, None)[inside])
        assert (len(got) < len(xyz)) == (crop is not None)


def _epoch_sums(part: dict, thinning: tuple) -> bytes:
    """The bytes of an epoch's thinning sums once a scan's ``part`` is added to them."""
    from soilvolume.distributed.scan import _add_in_order
    from soilvolume.inputs.thinning import ColumnThinner

    epoch = ColumnThinner(*thinning)
    _add_in_order(epoch, {0: part["sums"]}, 0)
    return epoch.sums.tobytes()


class _Recording:
    """A client that records what is submitted (the read-ahead of tiles)."""

    def __init__(self) -> None:
        self.submitted = []

    def submit(self, fn, *args, **kw):
        self.submitted.append((fn.__name__, args[0], kw.get("priority")))
        return ("future", args[0])


def _source(path: str, tiles: list[str]):
    from types import SimpleNamespace

    vpc = SimpleNamespace(tiles=[SimpleNamespace(path=p, count=10) for p in tiles])
    return SimpleNamespace(path=path, vpc=vpc, tiles=lambda: list(tiles))


def test_tiles_are_read_ahead_behind_the_scans_and_only_for_an_epoch_not_begun():
    """The later epoch's tiles are read ahead once the first epoch's scans are submitted (take
    submits nothing; prefetch, after them, does), at a lower priority; tiles already scanned are
    not; an epoch whose scan has begun (on the workers or in the driver) is not read ahead: that
    would read only the tiles of its wider expected region it does not scan."""
    client = _Recording()
    cache = pointcache.PointCache(client, 1.0)
    after, before = _source("a.vpc", ["a1", "a2"]), _source("b.vpc", ["b1", "b2", "b3"])
    cache.expect(before)
    assert cache.take(after, ["a1", "a2"]) == [(None, True), (None, True)] and client.submitted == []
    cache.prefetch()
    assert client.submitted == [("read_tile", p, -1) for p in ("b1", "b2", "b3")]
    assert cache.take(before, ["b1", "b2"]) == [(("future", "b1"), True), (("future", "b2"), True)]
    for begun in ("take", "hold"):
        client = _Recording()
        cache = pointcache.PointCache(client, 1.0)
        cache.expect(before)
        if begun == "take":
            cache.take(before, ["b1"])
        else:
            cache.hold(before, ("b1", "crop"), pointcache.KeptTile((), 10))
        cache.take(after, ["a1"])
        cache.prefetch()
        assert client.submitted == [], begun


def test_the_epoch_rule_is_decided_where_its_first_tile_was_read_ahead(vpcs, tmp_path, monkeypatch):
    """A worker that read the before's first tile ahead decides the epoch's rule on it (the
    driver does not decode that tile a second time); the same result as the driver deciding."""
    from soilvolume.distributed import cluster, scan

    monkeypatch.setattr(cluster.Starting, "ready", lambda self: True)  # up before the first tile
    monkeypatch.setattr(scan, "_first_rule", _counted_first_rule)  # (a task: pickled by reference)
    DECIDED.clear()
    got, eng = _run(vpcs, tmp_path / "tiled", "threads:2")
    assert len(DECIDED) == 1 and eng["task_points_from_memory"] > 0
    monkeypatch.setattr(pointcache, "CACHE_SHARE", 0.0)  # nothing read ahead: the driver decides
    ref, _ = _run(vpcs, tmp_path / "ref", "threads:2")
    assert len(DECIDED) == 1
    _identical(got, ref)


DECIDED: list = []  # the rules decided by tasks (threads: this module, imported by the workers)


def _counted_first_rule(*args):
    DECIDED.append(1)
    return _first_rule(*args)
