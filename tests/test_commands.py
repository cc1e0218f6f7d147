"""The shortened runs (``register``, ``dem``) go through the estimate's steps: each reads
exactly the options declared for it (``commands=`` in soilvolume/options/, from which the CLI
and QGIS build their inputs), and ``register`` decides the georeferencing as ``estimate`` does."""

from __future__ import annotations

import json
import os
from dataclasses import fields

import numpy as np
import pytest
from conftest import run_cli, write_scene

from soilvolume.core.hooks import Hooks
from soilvolume.options import Options, command_fields

READ: set[str] = set()
NAMES = {f.name for f in fields(Options)}


class Recording(Options):
    """Options that note every field read (copies made with ``with_`` are Recording too)."""

    def __getattribute__(self, name):
        if name in NAMES:
            READ.add(name)
        return super().__getattribute__(name)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("commands"), 5)


def _read_by(run, *variants: dict) -> set[str]:
    """The fields ``run(options)`` reads, over the defaults and each variant (the options some
    methods alone read: the coarse FPFH's voxel and seed, the PFH patch, the SMRF filter's)."""
    READ.clear()
    for changes in ({}, *variants):
        run(Recording(threads=1, **changes))
    return set(READ)


def test_register_reads_exactly_its_declared_options(pair, tmp_path):
    from soilvolume.workflow.commands import run_register

    before, after, _ = pair
    out = tmp_path / "r.laz"
    variant = {"coarse": "fpfh", "fine": "pfh", "ground": "filter"}
    used = _read_by(lambda o: run_register(before, after, out, o, hooks=Hooks()) and out.unlink(), variant)
    assert used == {f.name for f in command_fields("register")}


def test_dem_reads_exactly_its_declared_options(pair, tmp_path):
    from soilvolume.workflow.commands import run_cloud_to_dem

    before, _, _ = pair
    out = tmp_path / "d.tif"
    dem = lambda o: run_cloud_to_dem(before, out, o, crs=None, bounds=None, hooks=Hooks()) and out.unlink()  # noqa: E731
    used = _read_by(dem, {"ground": "filter"})
    assert used == {f.name for f in command_fields("dem")}


def test_register_honours_precise_georeferencing(pair, tmp_path):
    """--georeferencing precise: no registration, the identity, every point where it was."""
    import laspy

    before, after, _ = pair
    out = tmp_path / "registered.laz"
    done = run_cli("register", before, after, "--out", out, "--georeferencing", "precise", "--threads", "1")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["georeferencing"]["used"] == "precise"
    np.testing.assert_array_equal(np.array(result["transform"]), np.eye(4))
    moved, given = laspy.read(out), laspy.read(after)
    assert len(moved.points) == len(given.points)
    np.testing.assert_allclose(moved.xyz, given.xyz, atol=2e-3)  # LAS scale: millimetres


def test_register_registers_by_default(pair, tmp_path):
    """auto on a pair without a shared vertical datum: registered within the GPS prior (a real move)."""
    before, after, truth = pair
    done = run_cli("register", before, after, "--out", tmp_path / "r.laz")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["georeferencing"]["used"] == "gps"
    probe = np.array([500_079.0, 3_900_077.0, 60.0, 1.0])
    error = (np.array(result["transform"]) @ probe - np.array(truth["transform"]) @ probe)[:3]
    assert np.linalg.norm(error) < 0.1 and np.linalg.norm(np.array(truth["transform"])[:3, 3]) > 0.5


def test_timings_add_up_to_the_wall_time(pair, tmp_path):
    """report.json's timings_s: start-up, every stage and what no stage timed sum to the process's
    wall time (the process leaves without the interpreter's teardown once the report is out)."""
    import time

    before, after, _ = pair
    t0 = time.perf_counter()
    done = run_cli("estimate", before, after, "--out", tmp_path / "r", "--quiet")
    wall = time.perf_counter() - t0
    assert done.returncode == 0, done.stderr
    timings = json.loads((tmp_path / "r" / "report.json").read_text())["timings_s"]
    assert list(timings)[0] == "startup" and list(timings)[-1] == "other" and timings["startup"] > 0.05
    assert {"setup", "crop", "fine", "grids", "planes", "volume", "write", "report"} <= set(timings)
    tick = 1 / os.sysconf("SC_CLK_TCK")  # the start-up's resolution: the kernel's start time, in ticks
    assert 0.9 * wall <= sum(timings.values()) <= wall + tick, (sum(timings.values()), wall, timings)
