"""Bad input: a one-line error naming the file and the problem, a non-zero exit, nothing written."""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import run_cli

from soilvolume.inputs.io import write_las


def _las(path, xyz, crs="EPSG:32654"):
    write_las(path, np.asarray(xyz, float), None if crs is None else __import__("pyproj").CRS(crs).to_wkt())
    return path


def _grid_cloud(n=40, x0=500000.0, y0=3900000.0, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, n, size=(n * n, 2))
    z = 50 + np.sin(xy[:, 0] / 5) + np.cos(xy[:, 1] / 7)
    return np.c_[xy[:, 0] + x0, xy[:, 1] + y0, z]


@pytest.fixture
def good(tmp_path):
    b = _las(tmp_path / "before.las", _grid_cloud(60))
    a = _las(tmp_path / "after.las", _grid_cloud(30, seed=1))
    return b, a


def _fails(tmp_path, *args, expect: str):
    out = tmp_path / "out"
    p = run_cli("estimate", *args, "--out", out, "--quiet")
    assert p.returncode != 0
    msg = p.stderr.strip()
    assert msg.startswith("soilvolume: error:"), msg
    assert len(msg.splitlines()) == 1, msg
    assert expect.lower() in msg.lower(), msg
    assert not out.exists() or not any(out.iterdir()), "a failed run left files behind"
    return msg


def test_missing_file(tmp_path, good):
    msg = _fails(tmp_path, tmp_path / "nope.las", good[1], expect="file not found")
    assert "nope.las" in msg


def _as_nobody() -> list[str]:
    """The command prefix that runs a child as a user without root's right to read any file."""
    if os.geteuid() != 0:
        return []
    return [shutil.which("setpriv") or "/usr/bin/setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"]


def test_unreadable_file(good):
    """A file the user may not read: one line naming it, nothing written. As root (where every
    file is readable: CI's containers) the command runs as ``nobody`` in a folder it owns, with
    the locked file root's."""
    folder = Path(tempfile.mkdtemp(prefix="soilvolume-unreadable-"))  # /tmp: nobody reaches it
    try:
        if os.geteuid() == 0:
            os.chown(folder, pwd.getpwnam("nobody").pw_uid, -1)
        bad, after = folder / "locked.las", folder / "after.las"
        shutil.copy(good[0], bad)
        shutil.copy(good[1], after)
        bad.chmod(0)
        after.chmod(0o644)
        out = folder / "out"
        cmd = [*_as_nobody(), sys.executable, "-m", "soilvolume", "estimate", str(bad), str(after)]
        env = {**os.environ, "HOME": str(folder)}
        p = subprocess.run([*cmd, "--out", str(out), "--quiet"], capture_output=True, text=True, timeout=120, env=env)
        msg = p.stderr.strip()
        assert p.returncode != 0 and msg.startswith("soilvolume: error:"), (p.returncode, msg)
        assert len(msg.splitlines()) == 1 and "not readable" in msg and "locked.las" in msg, msg
        assert not out.exists() and sorted(x.name for x in folder.iterdir()) == ["after.las", "locked.las"]
    finally:
        shutil.rmtree(folder)


def test_corrupt_las(tmp_path, good):
    bad = tmp_path / "corrupt.las"
    bad.write_bytes(good[0].read_bytes()[:500])
    msg = _fails(tmp_path, bad, good[1], expect="corrupt.las")
    assert "las" in msg.lower()


def test_not_a_las_file(tmp_path, good):
    bad = tmp_path / "text.las"
    bad.write_text("this is not a point cloud\n")
    _fails(tmp_path, bad, good[1], expect="not a readable LAS/LAZ file")


def test_wrong_file_type(tmp_path, good):
    bad = tmp_path / "cloud.shp"
    bad.write_text("x")
    _fails(tmp_path, bad, good[1], expect="unsupported point cloud format")


def test_empty_cloud(tmp_path, good):
    empty = tmp_path / "empty.las"
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_crs(__import__("pyproj").CRS("EPSG:32654"))
    laspy.LasData(header).write(str(empty))
    _fails(tmp_path, empty, good[1], expect="empty")


def test_nan_coordinates(tmp_path, good):
    nan = tmp_path / "nan.xyz"
    xyz = _grid_cloud(20)
    xyz[5, 2] = np.nan
    np.savetxt(nan, xyz)
    _fails(tmp_path, good[0], nan, "--after-crs", "EPSG:32654", expect="NaN or infinite")


def test_no_crs_and_no_flag(tmp_path, good):
    nocrs = _las(tmp_path / "nocrs.las", _grid_cloud(30, seed=1), crs=None)
    msg = _fails(tmp_path, good[0], nocrs, expect="--after-crs")
    assert "nocrs.las" in msg and "no CRS" in msg


def test_crs_flag_makes_it_work(tmp_path, good):
    nocrs = _las(tmp_path / "nocrs.las", _grid_cloud(30, seed=1), crs=None)
    p = run_cli("estimate", good[0], nocrs, "--after-crs", "EPSG:32654", "--out", tmp_path / "o", "--quiet")
    assert p.returncode == 0, p.stderr


def test_bad_crs_text(tmp_path, good):
    _fails(tmp_path, good[0], good[1], "--after-crs", "EPSG:999999", expect="cannot understand CRS")


def test_crs_that_cannot_be_transformed(tmp_path, good):
    """Mars coordinates cannot be transformed to an Earth UTM zone."""
    mars = "+proj=utm +zone=10 +a=3396190 +b=3376200 +units=m +no_defs +type=crs"
    nocrs = _las(tmp_path / "nocrs.las", _grid_cloud(30, seed=1), crs=None)  # the flag applies to files without one
    _fails(tmp_path, good[0], nocrs, "--after-crs", mars, expect="transformation")


def test_no_overlap(tmp_path, good):
    far = _las(tmp_path / "far.las", _grid_cloud(30, x0=600000.0, seed=1))
    _fails(tmp_path, good[0], far, expect="do not overlap")


def test_registration_failure_is_reported(tmp_path, good):
    """A cloud of noise over the same footprint: no surface to register on."""
    rng = np.random.default_rng(5)
    noise = _grid_cloud(30, seed=1)
    noise[:, 2] = 50 + rng.uniform(-20, 20, len(noise))
    bad = _las(tmp_path / "noise.las", noise)
    _fails(tmp_path, good[0], bad, expect="registration failed")


def test_existing_output_without_overwrite(tmp_path, good):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    p = run_cli("estimate", good[0], good[1], "--out", out, "--quiet")
    assert p.returncode != 0 and "--overwrite" in p.stderr
    assert [f.name for f in out.iterdir()] == ["keep.txt"]


def test_inputs_are_never_modified(tmp_path, good):
    before = good[0].read_bytes(), good[1].read_bytes()
    p = run_cli("estimate", good[0], good[1], "--out", tmp_path / "o", "--quiet", "--coarse", "none")
    assert p.returncode == 0, p.stderr
    assert (good[0].read_bytes(), good[1].read_bytes()) == before


@pytest.mark.parametrize("link", ["same path", "symlink", "hardlink", "copy"])
def test_one_survey_as_before_and_after_is_refused(tmp_path, good, link):
    """The same file as before and after (by another path, a link, or its bytes copied) would
    give 0 ± 0 m3: estimate, register and volume refuse it naming both files; nothing written."""
    import os

    b = good[0]
    twin = b if link == "same path" else tmp_path / "twin.las"
    {"symlink": os.symlink, "hardlink": os.link, "copy": shutil.copyfile}.get(link, lambda *_: None)(b, twin)
    how = "a byte-for-byte copy of" if link == "copy" else "the same file as"
    before = {p: p.read_bytes() for p in (b, twin)}
    msg = _fails(tmp_path, b, twin, expect=f"{twin}: is {how} the before survey {b}")
    assert "two surveys" in msg
    for command, out in (("register", tmp_path / "r.laz"), ("volume", tmp_path / "v.tif")):
        done = run_cli(command, b, twin, "--out", out)
        assert done.returncode == 1 and done.stderr.count("\n") == 1 and f"is {how}" in done.stderr, done.stderr
        assert not out.exists()
    assert {p: p.read_bytes() for p in (b, twin)} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"before.las", "after.las", twin.name})
