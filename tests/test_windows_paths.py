"""Windows' and other systems' ways with files, simulated on Linux: a run's liveness test that is
no signal (``os.kill(pid, 0)`` is a Ctrl-C event on Windows), ``os.rename`` that refuses an
existing empty folder, and VPC ``file://`` hrefs with drive letters, UNC hosts or another computer."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import types

import numpy as np
import pytest

from soilvolume.core import outputs, siblings
from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs.io import write_las
from soilvolume.inputs.vpc import file_url_path, read_vpc, write_vpc


class SignalsRecorded(types.ModuleType):
    """``os`` as the outputs module sees it, its ``kill`` recorded (on Windows a Ctrl-C event)."""

    def __init__(self, sent: list) -> None:
        super().__init__("os")
        self.sent = sent

    def __getattr__(self, name: str):
        return getattr(os, name)

    def kill(self, pid: int, sig: int) -> None:
        self.sent.append((pid, sig))


def test_liveness_of_a_run_never_signals_it(monkeypatch):
    sent = []
    monkeypatch.setattr(siblings, "os", SignalsRecorded(sent))
    done = subprocess.run([sys.executable, "-c", "import os;print(os.getpid())"], capture_output=True, text=True)
    dead = int(done.stdout)
    with subprocess.Popen([sys.executable, "-c", "import time;time.sleep(30)"]) as alive:
        try:
            assert siblings._alive(alive.pid) and not siblings._alive(dead) and siblings._alive(os.getpid())
        finally:
            alive.kill()
    assert sent == []


def windows_rename(real):
    """``os.rename`` as on Windows: an existing destination, even an empty folder, is refused."""

    def rename(src, dst, *args, **kwargs):
        if os.path.lexists(dst):
            raise FileExistsError(errno.EEXIST, "Cannot create a file when that file already exists", str(dst))
        return real(src, dst, *args, **kwargs)

    return rename


@pytest.mark.parametrize("overwrite", [False, True])
def test_an_existing_empty_output_folder_is_filled_on_windows(tmp_path, monkeypatch, overwrite):
    monkeypatch.setattr(os, "rename", windows_rename(os.rename))
    out = tmp_path / "out"
    out.mkdir()
    with outputs.output_dir(out, [], overwrite) as staged:
        staged.path("report.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging or trash left
    with outputs.output_dir(out, [], True) as staged:  # a run over the old set: the trash path
        staged.path("report.json").write_text('{"second": 1}')
    assert json.loads((out / "report.json").read_text()) == {"second": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_folder_filled_meanwhile_is_still_refused_on_windows(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "rename", windows_rename(os.rename))
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(SoilVolumeError, match="filled the output folder meanwhile"):
        with outputs.output_dir(out, [], False) as staged:
            staged.path("report.json").write_text("{}")
            (out / "theirs.txt").write_text("another run's")
    assert sorted(p.name for p in out.iterdir()) == ["theirs.txt"]


@pytest.mark.parametrize(
    ("url", "path"),
    [
        ("file:///C:/surveys/2024/tile%201.laz", r"C:\surveys\2024\tile 1.laz"),
        ("file:///c|/surveys/t.laz", r"C:\surveys\t.laz"),
        ("file://nas01/share/surveys/t.laz", r"\\nas01\share\surveys\t.laz"),
        ("file:////nas01/share/t.laz", r"\\nas01\share\t.laz"),
        ("file://localhost/C:/t.laz", r"C:\t.laz"),
    ],
)
def test_file_urls_on_windows(url, path):
    assert file_url_path(url, windows=True) == path


def test_file_urls_elsewhere():
    assert file_url_path("file:///data/tile%201.laz", windows=False) == "/data/tile 1.laz"
    assert file_url_path("file://localhost/data/t.laz", windows=False) == "/data/t.laz"
    with pytest.raises(ValueError, match="another computer"):
        file_url_path("file://nas01/data/t.laz", windows=False)


def test_a_vpc_tile_on_another_computer_is_refused_not_read_locally(tmp_path):
    """``file://nas01/<path>`` names the file on nas01; it was read from this computer's <path>."""
    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(500_000, 500_010, 200), rng.uniform(4_000_000, 4_000_010, 200), rng.uniform(0, 1, 200)]
    import pyproj

    tile = tmp_path / "tile.laz"
    write_las(tile, xyz, pyproj.CRS("EPSG:32654").to_wkt(), np.full(200, 2, np.uint8))
    vpc = write_vpc(tmp_path / "s.vpc", [tile], relative=False)
    doc = json.loads(vpc.read_text())
    doc["features"][0]["assets"]["data"]["href"] = f"file://nas01{tile.as_posix()}"
    vpc.write_text(json.dumps(doc))
    before = vpc.read_bytes()
    with pytest.raises(SoilVolumeError, match=r"s\.vpc: .*file://nas01.* is on another computer \(nas01\)"):
        read_vpc(vpc)
    doc["features"][0]["assets"]["data"]["href"] = f"file://localhost{tile.as_posix()}"
    vpc.write_text(json.dumps(doc))
    assert read_vpc(vpc).count == 200
    assert before != vpc.read_bytes()
