"""More of a hostile user: devices and pipes as inputs or outputs, a full disk under the LAZ
writer, impossible header bounds, absurd worker counts and crop radii, a signal during start-up."""

from __future__ import annotations

import os
import stat
import struct

import numpy as np
import pytest
from conftest import run_python, write_scene
from test_robustness import WKT, _cloud, _hidden, _one_line_error, cli, small_pair

from soilvolume import api
from soilvolume.core.types import SoilVolumeError
from soilvolume.distributed.schedule import parse
from soilvolume.inputs.io import write_las
from soilvolume.inputs.stream import ColumnThinner


@pytest.fixture
def pair(tmp_path):
    return small_pair(tmp_path)


def test_a_single_file_output_never_replaces_a_device_or_pipe(capsys, pair, tmp_path):
    fifo = tmp_path / "out.tif"
    os.mkfifo(fifo)
    for args in (["dem", pair[0]], ["register", *pair], ["volume", *pair]):
        code, err = cli(capsys, *args, "--out", fifo)
        _one_line_error(code, err, "out.tif", "not a regular file")
        assert stat.S_ISFIFO(fifo.lstat().st_mode)


def test_pipes_and_devices_as_inputs_are_refused_without_hanging(capsys, pair, tmp_path, alarm):
    fifo = tmp_path / "fifo.gpkg"
    os.mkfifo(fifo)
    out = tmp_path / "o"
    cases = [
        (["estimate", *pair, "--out", out, "--before-pipeline", fifo], "fifo.gpkg"),
        (["estimate", *pair, "--out", out, "--before-pipeline", "/dev/zero"], "/dev/zero"),
        (["estimate", *pair, "--out", out, "--zones", fifo], "fifo.gpkg"),
        (["volume", fifo, pair[1], "--out", tmp_path / "v.tif"], "fifo.gpkg"),
    ]
    for args, name in cases:
        code, err = cli(capsys, *args, *(["--quiet"] if args[0] == "estimate" else []))
        _one_line_error(code, err, name, "not a regular file")
    assert not out.exists() and not (tmp_path / "v.tif").exists()


def test_a_pipeline_file_larger_than_any_pipeline_is_not_read(capsys, pair, tmp_path, monkeypatch):
    from soilvolume.pipelines import load

    big = tmp_path / "big.json"
    big.write_text("[" + " " * 4096 + "]")
    monkeypatch.setattr(load, "MAX_BYTES", 1024)
    code, err = cli(capsys, "estimate", *pair, "--out", tmp_path / "o", "--before-pipeline", big, "--quiet")
    _one_line_error(code, err, "big.json", "larger than")


def test_a_full_disk_under_the_laz_writer_is_one_line_and_leaves_nothing(capsys, pair, tmp_path, monkeypatch):
    import laspy
    import lazrs

    def full(self, *args, **kwargs):
        raise lazrs.LazrsError("IoError: Failed to call write")

    monkeypatch.setattr(laspy.LasWriter, "write_points", full)
    code, err = cli(capsys, "register", *pair, "--out", tmp_path / "r.laz")
    _one_line_error(code, err, "r.laz", "cannot write")
    code, err = cli(capsys, "estimate", *pair, "--out", tmp_path / "o", "--registered-cloud", "--quiet")
    _one_line_error(code, err, "cannot write")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["after.las", "before.las"]


@pytest.mark.parametrize(
    ("at", "value"),
    [
        (187, 1e300),  # min x far beyond what offset + scale * int32 can reach
        (195, 3899000.0),  # max y below min y
    ],
)
def test_impossible_header_bounds_are_refused_before_reading(capsys, tmp_path, at, value):
    path = tmp_path / "bounds.las"
    write_las(path, _cloud(20), WKT)
    data = bytearray(path.read_bytes())
    struct.pack_into("<d", data, at, value)
    path.write_bytes(bytes(data))
    code, err = cli(capsys, "dem", path, "--out", tmp_path / "d.tif")
    _one_line_error(code, err, "bounds.las", "corrupt LAS header", "bounds")


def test_bounds_far_beyond_the_points_cost_no_memory(capsys, tmp_path):
    path = tmp_path / "far.las"
    write_las(path, _cloud(20), WKT)
    data = bytearray(path.read_bytes())
    offset_y = struct.unpack_from("<d", data, 163)[0]
    struct.pack_into("<d", data, 195, offset_y + 2.0e6)  # storable, but 2000 km past the points
    path.write_bytes(bytes(data))
    code, err = cli(capsys, "dem", path, "--out", tmp_path / "d.tif")
    _one_line_error(code, err, "far.las", "far larger than the points")


def test_a_thinner_cut_to_the_data_gives_the_same_columns():
    rng = np.random.default_rng(3)
    xyz = np.c_[rng.uniform(100, 160, (5000, 2)), rng.normal(0, 1, 5000)]
    whole = ColumnThinner(np.zeros(2), np.full(2, 2000.0), 0.7)
    cut = ColumnThinner(np.zeros(2), np.full(2, 2000.0), 0.7, within=(np.full(2, 99.0), np.full(2, 161.0)))
    for part in np.array_split(xyz, 3):
        whole.add(part)
        cut.add(part)
    assert cut.sums.shape[1] < whole.sums.shape[1] / 100
    assert np.array_equal(cut.columns()[0], whole.columns()[0])
    assert np.array_equal(cut.columns()[1], whole.columns()[1])


def test_a_crop_radius_far_larger_than_the_before_cloud_runs_small(pair, tmp_path):
    res = api.estimate(*pair, tmp_path / "o", api.Options(radius=10000.0))
    assert res.report["options"]["radius"] == 10000.0


@pytest.mark.parametrize("spec", ["local:0", "local:99999", "threads:1025"])
def test_absurd_worker_counts_are_refused(spec):
    with pytest.raises(SoilVolumeError, match="N from 1 to 1024"):
        parse(spec)


def test_a_before_cloud_of_three_points_is_not_called_an_overlap_problem(capsys, pair, tmp_path):
    three = tmp_path / "three.las"
    write_las(three, np.array([[500010.0, 3900010, 50], [500020, 3900010, 51], [500010, 3900020, 52]]), WKT)
    code, err = cli(capsys, "estimate", three, pair[1], "--out", tmp_path / "o", "--quiet")
    _one_line_error(code, err, "three.las", "too few points")


@pytest.mark.parametrize(
    "start",
    [
        "runpy.run_module('soilvolume', run_name='__main__')",  # python -m soilvolume
        "from soilvolume.__main__ import run; sys.exit(run())",  # the console command
    ],
    ids=["module", "console"],
)
def test_a_signal_while_the_program_is_still_importing_is_one_line(start):
    from importlib.metadata import entry_points

    assert entry_points(group="console_scripts")["soilvolume"].value == "soilvolume.__main__:run"
    script = (
        "import builtins, os, signal, runpy, sys\n"
        "real = builtins.__import__\n"
        "def slow(name, globals=None, locals=None, fromlist=(), level=0):\n"
        "    if name == 'cli' and level == 1:\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "    return real(name, globals, locals, fromlist, level)\n"
        "builtins.__import__ = slow\n"
        "sys.argv = ['soilvolume', '--help']\n"
        f"{start}\n"
    )
    done = run_python(script)
    assert done.returncode == 130, done.stderr
    assert done.stderr.splitlines() == ["soilvolume: error: interrupted by SIGINT; nothing was written"]


def _capped(limit: int, *args, before: str = "") -> tuple[int, list[str]]:
    """The command line in a process that may write no file past ``limit`` bytes (RLIMIT_FSIZE: the
    write that crosses it fails, EFBIG, as on a full disk; SIGXFSZ ignored), ``before`` run first:
    (exit code, stderr lines)."""
    import resource
    import signal
    import subprocess
    import sys

    def cap() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    main = "import sys; from soilvolume.cli import main; sys.exit(main(sys.argv[1:]))"
    cmd = [sys.executable, "-c", f"{before}\n{main}", *map(str, args)]
    done = subprocess.run(cmd, preexec_fn=cap, capture_output=True, text=True, timeout=300)
    return done.returncode, done.stderr.strip().splitlines()


def _dem_pair(folder) -> tuple:
    """Two 300 x 300 DEM GeoTIFFs of noise (their difference compresses badly: a large file)."""
    import rasterio
    from rasterio.transform import from_origin

    rng, paths = np.random.default_rng(0), []
    for name in ("b.tif", "a.tif"):
        with rasterio.open(
            folder / name, "w", driver="GTiff", width=300, height=300, count=1, dtype="float64",
            crs="EPSG:32654", transform=from_origin(500000, 3900300, 1.0, 1.0),
        ) as ds:  # fmt: skip
            ds.write(rng.normal(50, 1, (300, 300)), 1)
        paths.append(folder / name)
    return tuple(paths)


def _sums(folder) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


@pytest.mark.skipif(not hasattr(os, "fork"), reason="RLIMIT_FSIZE is POSIX")
@pytest.mark.parametrize("command", ["volume", "dem"])
def test_a_raster_cut_off_by_a_full_disk_is_an_error_and_is_not_left(tmp_path, command):
    """GDAL ignores a write that fails as it closes a GeoTIFF: the file was left short by its last
    bytes and the command said done. One line naming the file, exit 1, nothing written."""
    inputs = tmp_path / "in"
    inputs.mkdir()
    args = [*_dem_pair(inputs)] if command == "volume" else [write_scene(inputs)[1], "--cell", "0.2"]
    whole = tmp_path / "whole.tif"
    code, err = _capped(1 << 40, command, *args, "--out", whole)
    assert code == 0 and whole.stat().st_size > 100_000, err
    before = _sums(inputs)
    out = tmp_path / "out" / "short.tif"
    out.parent.mkdir()
    code, err = _capped(whole.stat().st_size - 1, command, *args, "--out", out)
    _one_line_error(code, err, str(out), "file too large")
    assert list(out.parent.iterdir()) == [] and _sums(inputs) == before


@pytest.mark.skipif(not hasattr(os, "fork"), reason="RLIMIT_FSIZE is POSIX")
@pytest.mark.parametrize("scheduler", ["none", "threads:1", "threads:1 on disk"])
def test_an_estimate_raster_cut_off_by_a_full_disk_fails_the_run(tmp_path, scheduler):
    """The estimate's largest raster one byte short of room (in-process: dem/geotiff.write_grid; tiled:
    its COG writer, its raster staged in memory or, as a large one is, on disk): the run fails naming
    that raster, and no output folder appears."""
    disk = "from soilvolume.dem import geotiff; geotiff.IN_MEMORY_CELLS = 0" if "disk" in scheduler else ""
    scheduler = scheduler.split()[0]
    inputs = tmp_path / "in"
    inputs.mkdir()
    pair = write_scene(inputs)[:2]  # rough ground: 0.2 m DEMs compress to more than the reports
    tiles = ["--tile-cells", "64"] if scheduler != "none" else []  # its scratch tiles smaller than a raster
    args = ["estimate", *pair, "--cell", "0.2", "--scheduler", scheduler, *tiles, "--quiet", "--out"]
    code, err = _capped(1 << 40, *args, tmp_path / "whole", before=disk)
    assert code == 0, err
    sizes = {p.name: p.stat().st_size for p in (tmp_path / "whole").iterdir()}
    largest = max(sizes, key=sizes.get)
    others = max(s for n, s in sizes.items() if n != largest)
    assert largest.endswith(".tif") and others < sizes[largest] - 1, sizes  # only that raster fails
    before = _sums(inputs)
    code, err = _capped(sizes[largest] - 1, *args, tmp_path / "out", before=disk)
    _one_line_error(code, err, largest, "file too large" if not disk else "cut off")
    assert not (tmp_path / "out").exists() and _hidden(tmp_path) == [] and _sums(inputs) == before


@pytest.mark.parametrize("vertex", ["[NaN, NaN]", "[500020, NaN]", "[Infinity, 3900020]"])
def test_a_zone_with_a_coordinate_that_is_not_a_number_is_one_line(tmp_path, vertex):
    """A GeoJSON vertex of NaN or infinity (GDAL reads them): shapely's make_valid raised GEOS's
    exception and the run ended in a traceback, with GEOS's warnings before it. One line naming the
    file and the zone for volume and estimate, on the zones and the stable-ground mask alike."""
    from conftest import run_cli

    inputs = tmp_path / "in"
    inputs.mkdir()
    pair, dems = small_pair(inputs), _dem_pair(inputs)
    ring = f"[[500000, 3900000], [500020, 3900000], {vertex}, [500000, 3900020], [500000, 3900000]]"
    zones = inputs / "zones.geojson"
    zones.write_text(
        '{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"name": "pit"}, '
        f'"geometry": {{"type": "Polygon", "coordinates": [{ring}]}}}}]}}'
    )
    before = _sums(inputs)
    for args in (
        ["volume", *dems, "--out", tmp_path / "v.tif", "--zones", zones],
        ["estimate", *pair, "--out", tmp_path / "o", "--quiet", "--zones", zones],
        ["estimate", *pair, "--out", tmp_path / "o", "--quiet", "--stable-mask", zones],
    ):
        done = run_cli(*args)
        _one_line_error(done.returncode, done.stderr.strip().splitlines(), "zones.geojson", "'pit'", "not a number")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"] and _sums(inputs) == before


@pytest.mark.skipif(not hasattr(os, "fork"), reason="RLIMIT_NOFILE is POSIX")
def test_too_few_open_files_for_a_local_cluster_is_one_line_naming_the_limit(tmp_path):
    """``ulimit -n 24`` with --scheduler local:2: Dask's scheduler spun on accept() for minutes,
    printing its traceback millions of times, before a line naming a scratch folder. Now one line
    naming the limit and the remedies, at once; nothing written."""
    import resource
    import subprocess
    import sys

    inputs = tmp_path / "in"
    inputs.mkdir()
    pair = small_pair(inputs)
    before, err = _sums(inputs), tmp_path / "stderr.txt"

    def few() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (24, 24))

    cmd = [sys.executable, "-m", "soilvolume", "estimate", *map(str, pair), "--out", str(tmp_path / "o"), "--quiet"]
    with open(err, "w") as fh:  # a file: the old behaviour wrote gigabytes
        code = subprocess.run([*cmd, "--scheduler", "local:2"], preexec_fn=few, stderr=fh, timeout=60).returncode
    lines = err.read_text().splitlines()
    _one_line_error(code, lines, "--scheduler local:2", "open-file limit (ulimit -n) is 24", "--scheduler none")
    err.unlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"] and _sums(inputs) == before
    script = (
        "import resource; from soilvolume.distributed.schedule import choose\n"
        "print(choose(4.0, 10**9).kind)\n"
        "resource.setrlimit(resource.RLIMIT_NOFILE, (24, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))\n"
        "print(choose(4.0, 10**9).kind)\n"
    )
    done = run_python(script)  # auto: worker processes while the limit holds them, else threads
    assert done.stdout.split() == ["local", "threads"], done.stderr
