"""What kept tiles are keyed by (every input's content, every option that changes numbers), and
the run stores: one per run, kept only after an interruption, claimed by one run only."""

from __future__ import annotations

import json
import os
import shutil
import signal
from dataclasses import fields, replace

import numpy as np
import pyproj
import pytest
from test_robustness import WKT, _cloud

from soilvolume.core.interrupt import Interrupted
from soilvolume.core.types import GridSpec
from soilvolume.distributed import tilestore
from soilvolume.distributed.gridtile import Plan
from soilvolume.distributed.tilestore import RunStore, run_store
from soilvolume.distributed.tiletask import plan_parts
from soilvolume.inputs.crs import WorkFrame
from soilvolume.inputs.io import write_las
from soilvolume.inputs.vpc import write_vpc
from soilvolume.options import Options
from soilvolume.soil.points import PointRule

#: a value of each option other than its default (the test fails when an option is added
#: without one, so that a new option is checked to key the tiles, or declared run control)
OTHER = {
    "before_crs": "EPSG:32654",
    "after_crs": "EPSG:32654",
    "radius": 31.0,
    "design_uncertainty": 0.05,
    "design_surface": "finished grade",
    "coarse": "fpfh",
    "coarse_voxel": 2.0,
    "georeferencing": "precise",
    "max_gps_shift": 9.0,
    "max_gps_rotation": 7.0,
    "max_gps_tilt": 2.0,
    "fine": "gicp",
    "pfh_patch": 7.0,
    "seed": 1,
    "correction": "plane",
    "plane_threshold": 0.2,
    "cell": 2.0,
    "statistic": "mean",
    "min_count_ratio": 0.2,
    "fill_holes": 50.0,
    "fill_method": "harmonic",
    "ground": "none",
    "ground_window": 7.0,
    "ground_slope": 0.7,
    "exclude": "none",
    "objects": "count",
    "lod_confidence": 0.9,
    "threads": 2,
    "scheduler": "local:2",
    "memory_limit": 4.0,
    "tile_cells": 64,
    "volume_step": "tiles",
    "keep_registered_cloud": True,
    "contour_interval": 0.5,
    "sections": "lines.geojson",
    "gpkg": True,
    "design": "design.tif",
    "bulking": 1.25,
    "shrinkage": 0.9,
    "tolerance": 0.05,
    "base": "plane",
    "density": 1.8,
}
FILES = ("zones", "stable_mask")


def _polygons(path, x0: float = 500000.0) -> str:
    box = [[[x0, 3900000], [x0 + 10, 3900000], [x0 + 10, 3900010], [x0, 3900010], [x0, 3900000]]]
    feature = {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": box}}
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    return str(path)


def test_every_option_but_run_control_keys_the_tiles(tmp_path):
    plain = tilestore.number_options(Options())
    run_control = {f.name for f in fields(Options) if f.metadata["run_control"]}
    # contours and sections are drawn from the rasters written: they never change a tile's numbers
    assert run_control == {
        "threads",
        "scheduler",
        "memory_limit",
        "keep_registered_cloud",
        "contour_interval",
        "sections",
        "gpkg",
    }
    for f in fields(Options):
        if f.name in FILES:
            changed = Options(**{f.name: _polygons(tmp_path / f"{f.name}.geojson")})
        else:
            assert f.name in OTHER, f"{f.name}: give it a value in OTHER"
            changed = Options(**{f.name: OTHER[f.name]})
        differs = tilestore.number_options(changed) != plain
        assert differs != (f.name in run_control), f.name


def test_a_changed_polygon_file_changes_the_key(tmp_path):
    path = _polygons(tmp_path / "z.geojson")
    a = tilestore.number_options(Options(zones=path))
    _polygons(tmp_path / "z.geojson", 500001.0)
    b = tilestore.number_options(Options(zones=path))
    assert a != b
    why = tilestore.difference({"options": a}, {"options": b, "inputs": {}, "code": None})
    assert why in ("the engine's code changed", "the --zones file z.geojson changed")


def test_the_identity_of_a_file_follows_its_content(tmp_path):
    path = tmp_path / "a.las"
    write_las(path, _cloud(30), WKT)
    st = path.stat()
    first = tilestore.file_identity(path)
    data = bytearray(path.read_bytes())
    data[-5] ^= 0xFF  # one byte of a point, the size and the modification time kept
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert tilestore.file_identity(path) != first
    assert tilestore.file_identity(path)["size"] == first["size"]


def test_large_files_are_sampled_not_read_whole(tmp_path, monkeypatch):
    monkeypatch.setattr(tilestore, "WHOLE_BYTES", 1000)
    path = tmp_path / "big.bin"
    body = bytearray(np.random.default_rng(0).integers(0, 255, 300_000, dtype=np.uint8).tobytes())
    path.write_bytes(bytes(body))
    first = tilestore.file_identity(path)
    body[100] ^= 1  # in the head
    path.write_bytes(bytes(body))
    assert tilestore.file_identity(path)["hash"] != first["hash"]


def test_a_vpc_is_identified_by_its_tiles_too(tmp_path):
    tiles = []
    for k in range(2):
        tiles.append(tmp_path / f"t{k}.laz")
        write_las(tiles[-1], _cloud(20, x0=500000.0 + 20 * k), WKT)
    vpc = write_vpc(tmp_path / "s.vpc", tiles)
    first = tilestore.input_identity(vpc)
    assert set(first) == {str(vpc), *(str(t.resolve()) for t in tiles)}
    xyz = _cloud(20, x0=500020.0)
    xyz[:, 2] += 1.0
    write_las(tiles[1], xyz, WKT)  # the same box, other heights
    again = tilestore.input_identity(vpc)
    assert again != first
    why = tilestore.difference({"code": "c", "inputs": {"before": first}}, {"code": "c", "inputs": {"before": again}})
    assert why == "t1.laz changed (size, modification time or content)"


def test_an_interrupted_run_keeps_its_tiles_and_only_one_run_claims_them(tmp_path):
    final = tmp_path / "out"
    parts = {"code": "c", "inputs": {}, "options": {"cell": 1.0}, "plan": {}}
    with pytest.raises(Interrupted, match=r"kept in .*\.out\.soilvolume-tiles"), run_store(final) as store:
        store.bind(parts)
        store.tiles([(0, 2, 0, 2)]).save((0, 2, 0, 2), {"h": np.ones((2, 2))})
        raise Interrupted(signal.SIGINT)
    kept = tmp_path / ".out.soilvolume-tiles"
    assert kept.is_dir()
    first, second = RunStore(final), RunStore(final)  # two runs: one claims the tiles
    assert (first.claimed, second.claimed) == (True, False) and first.folder != second.folder
    assert first.bind(parts) is None and first.tiles([(0, 2, 0, 2)]).has(["h"], (0, 2, 0, 2))
    said = second.bind({**parts, "options": {"cell": 2.0}})
    assert said is None  # nothing of its own to discard
    first.close(keep=False)
    second.close(keep=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_kept_tiles_of_other_options_are_discarded_with_the_reason(tmp_path):
    final = tmp_path / "out"
    parts = {"code": "c", "inputs": {}, "options": {"cell": 1.0}, "plan": {}}
    store = RunStore(final)
    store.bind(parts)
    store.tiles([(0, 2, 0, 2)]).save((0, 2, 0, 2), {"h": np.ones((2, 2))})
    (store.folder / f".{store.key}_h_2_4_0_2.npy.4242-abcd1234").write_bytes(b"cut short")  # a killed writer's
    assert store.close(keep=True)
    assert sorted(p.name for p in (tmp_path / ".out.soilvolume-tiles").iterdir()) == [
        f"{store.key}_h_0_2_0_2.npy",
        "store.json",
    ]
    again = RunStore(final)
    said = again.bind({**parts, "options": {"cell": 2.0}})
    assert (
        said == "discarding the tiles kept by an interrupted run: --cell differs (1.0 then, 2.0 now); starting afresh"
    )
    assert not again.tiles([(0, 2, 0, 2)]).has(["h"], (0, 2, 0, 2))
    again.close(keep=False)


def test_a_failed_run_keeps_nothing_and_a_killed_runs_store_is_swept(tmp_path):
    final = tmp_path / "out"
    with pytest.raises(ValueError), run_store(final) as store:
        store.bind({"code": "c", "inputs": {}, "options": {}, "plan": {}})
        store.tiles([(0, 1, 0, 1)]).save((0, 1, 0, 1), {"h": np.ones((1, 1))})
        raise ValueError("a failure")
    assert list(tmp_path.iterdir()) == []
    dead = tmp_path / ".out.soilvolume-tiles-999999999-abcd1234"
    dead.mkdir()
    RunStore(final).close(keep=False)
    assert list(tmp_path.iterdir()) == []


def test_kept_tiles_of_an_older_version_a_file_or_a_link_are_never_trusted(tmp_path):
    final = tmp_path / "out"
    old = tmp_path / ".out.soilvolume-tiles" / "0123456789abcdef"
    old.mkdir(parents=True)
    (old / "tile_0_1_0_1.npz").write_bytes(b"old")
    store = RunStore(final)
    assert store.bind({"code": "c"}) == (
        "discarding the tiles kept by an interrupted run: they carry no record of their inputs; starting afresh"
    )
    store.close(keep=False)
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "precious.txt").write_text("keep me")
    for planted in ("link", "file"):
        kept = tmp_path / ".out.soilvolume-tiles"
        kept.symlink_to(victim) if planted == "link" else kept.write_text("x")
        store = RunStore(final)
        assert not store.claimed and store.bind({"code": "c"}) is None
        store.tiles([(0, 1, 0, 1)]).save((0, 1, 0, 1), {"h": np.ones((1, 1))})
        assert store.close(keep=True) and kept.is_dir() and not kept.is_symlink()
        shutil.rmtree(kept)
    assert [p.name for p in victim.iterdir()] == ["precious.txt"]


class _CyclicJunk:
    """Garbage in a reference cycle with a finaliser: the collector runs Python code, where the
    interpreter may switch threads (inside another thread's AST construction too)."""

    def __init__(self) -> None:
        self.me = self

    def __del__(self) -> None:
        sum(range(50))


def test_tiles_load_from_many_threads_at_once(tmp_path):
    """A threads:N run's tasks load tiles at the same time: numpy parses each .npy header with
    ast.literal_eval, which CPython 3.11 cannot run in two threads at once (a spurious
    "SystemError: AST constructor recursion depth mismatch", python/cpython#106905; 868 of
    20 000 bare loads failed so on this machine's 3.11.2). The store's loads take turns."""
    import gc
    import sys
    import threading

    from soilvolume.distributed.tilestore import TileStore

    store = TileStore(str(tmp_path), ((0, 16, 0, 16),))
    store.save((0, 16, 0, 16), {"dem": np.arange(256.0).reshape(16, 16)})
    errors: list[str] = []

    def work() -> None:
        for _ in range(1000):
            [_CyclicJunk() for _ in range(5)]
            try:
                assert store.load("dem", (0, 16, 0, 16))[3, 4] == 52.0
            except SystemError as exc:
                errors.append(str(exc))

    old = sys.getswitchinterval(), gc.get_threshold()
    sys.setswitchinterval(1e-6)
    gc.set_threshold(50, 5, 5)
    try:
        threads = [threading.Thread(target=work) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
    finally:
        sys.setswitchinterval(old[0])
        gc.set_threshold(*old[1])
    assert not any(t.is_alive() for t in threads)
    assert errors == []


def _plan_parts(windows=((0, 40, 0, 40),), k: int = 1, **changed) -> dict:
    """The key parts of a small run's tile plan (:func:`tiletask.plan_parts`), with ``changed``
    fields, cut into ``windows``, its overview ``k`` x ``k`` cells."""
    crs = pyproj.CRS("EPSG:32654")
    plan = Plan(
        "b.las",
        "a.las",
        crs.to_wkt(),
        crs.to_wkt(),
        WorkFrame(crs, 1.0),
        np.zeros(3),
        GridSpec(0.0, 40.0, 1.0, 40, 40),
        np.eye(4),
        (False, False),
        np.zeros((3, 2)),
        "mean",
    )
    return tilestore.run_parts({}, Options(), plan_parts(replace(plan, **changed), list(windows), k))


def test_every_field_of_the_tile_plan_keys_the_tiles():
    """Tiles are reused only for the same frame, grid, registration, crop, statistic, ground,
    rules and chunk index: every field of the plan is in the key (a new one too), but the files'
    names (their content is keyed) and what the driver opened of them."""
    plain = _plan_parts()
    shifted = np.eye(4)
    shifted[0, 3] = 1e-9  # a registration moved by a nanometre
    other = {
        "crs_b": pyproj.CRS("EPSG:32655").to_wkt(),
        "crs_a": pyproj.CRS("EPSG:32655").to_wkt(),
        "frame": WorkFrame(pyproj.CRS("EPSG:32655"), 1.0),
        "origin": np.ones(3),
        "grid": GridSpec(0.0, 40.0, 1.0, 40, 41),
        "transform": shifted,
        "ground": (True, False),
        "crop": np.ones((3, 2)),
        "statistic": "median",
        "index": (((0, 10, 0.0, 0.0, 1.0, 1.0),), None),
        "rules": (PointRule(), None),
    }
    opened = {"sources": ("opened", None), "mask": "a lattice", "before": "c.las", "after": "d.las"}
    for f in fields(Plan):
        if f.name in opened:
            assert _plan_parts(**{f.name: opened[f.name]}) == plain, f.name
            continue
        assert f.name in other, f"{f.name}: give it a value in `other`"
        changed = _plan_parts(**{f.name: other[f.name]})
        assert tilestore.difference(plain, changed) == "the registration, grid or tiling differs", f.name
    for other_cut in (_plan_parts(windows=((0, 20, 0, 40), (20, 40, 0, 40))), _plan_parts(k=2)):
        assert tilestore.difference(plain, other_cut) == "the registration, grid or tiling differs"
