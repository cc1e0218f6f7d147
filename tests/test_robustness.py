"""A hostile or careless user: inputs are never written, every option is checked, OS faults and
broken headers give one line naming the path, and the output set is all-or-nothing."""

from __future__ import annotations

import errno
import hashlib
import json
import math
import struct
import sys
from dataclasses import fields
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
from conftest import run_python

from soilvolume import api
from soilvolume.cli import main
from soilvolume.core.outputs import OutputDir, sweep
from soilvolume.core.types import SoilVolumeError
from soilvolume.inputs.io import write_las
from soilvolume.options import Options
from soilvolume.validate import OptionError, check_options

WKT = pyproj.CRS("EPSG:32654").to_wkt()


def _cloud(n=40, x0=500000.0, y0=3900000.0, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, n, size=(n * n, 2))
    z = 50 + np.sin(xy[:, 0] / 5) + np.cos(xy[:, 1] / 7)
    return np.c_[xy[:, 0] + x0, xy[:, 1] + y0, z]


def small_pair(folder: Path) -> tuple[Path, Path]:
    """Two small overlapping LAS clouds in ``folder``: (before, after)."""
    b, a = folder / "before.las", folder / "after.las"
    write_las(b, _cloud(60), WKT)
    write_las(a, _cloud(30, seed=1), WKT)
    return b, a


@pytest.fixture
def pair(tmp_path):
    return small_pair(tmp_path)


def _md5(*paths):
    return [hashlib.md5(Path(p).read_bytes()).hexdigest() for p in paths]


def cli(capsys, *args) -> tuple[int, list[str]]:
    """The command line in-process: (exit code, stderr lines)."""
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


def _one_line_error(code, err, *expect):
    assert code == 1, err
    assert len(err) == 1 and err[0].startswith("soilvolume: error: "), err
    for text in expect:
        assert text.lower() in err[0].lower(), err


def _hidden(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if "soilvolume-" in p.name]


# ------------------------------------------------------------------------------------ options
@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--cell", "nan"),
        ("--cell", "inf"),
        ("--cell", "-1"),
        ("--cell", "1e9"),
        ("--radius", "nan"),
        ("--radius", "-5"),
        ("--lod-confidence", "1.5"),
        ("--seed", "-1"),
        ("--pfh-patch", "0"),
        ("--ground-window", "nan"),
        ("--ground-slope", "inf"),
        ("--threads", "-2"),
        ("--max-gps-shift", "-inf"),
    ],
)
def test_absurd_option_is_refused_naming_it_and_its_range(capsys, tmp_path, flag, value):
    out = tmp_path / "out"
    code, err = cli(capsys, "estimate", "b.las", "a.las", "--out", out, f"{flag}={value}")
    _one_line_error(code, err, f"error: {flag}: must be", "(got ")
    assert not out.exists()


@pytest.mark.parametrize(
    "args",
    [
        ["--cell", "nan"],
        ["--bounds", "nan", "0", "10", "10"],
        ["--bounds", "10", "10", "0", "0"],
        ["--bounds", "0", "0", "inf", "10"],
    ],
)
def test_dem_options_are_checked(capsys, tmp_path, args):
    code, err = cli(capsys, "dem", "cloud.las", "--out", tmp_path / "d.tif", *args)
    _one_line_error(code, err, args[0])
    assert not (tmp_path / "d.tif").exists()


def test_every_declared_range_is_enforced_by_the_engine():
    check_options(Options())
    for f in fields(Options):
        lo, hi = f.metadata["lo"], f.metadata["hi"]
        if lo is None:
            continue
        for bad in (lo - 1, hi * 2 + 1, math.nan):
            with pytest.raises(OptionError) as info:
                check_options(Options(**{f.name: int(bad) if f.type == "int" and bad == bad else bad}))
            assert info.value.field == f.name and str(info.value).startswith("--" + f.name.replace("_", "-"))


def test_api_entry_points_validate_too(pair, tmp_path):
    with pytest.raises(OptionError, match="--cell"):
        api.estimate(*pair, tmp_path / "o", Options(cell=math.inf))
    with pytest.raises(OptionError, match="--seed"):
        api.register(*pair, tmp_path / "r.laz", Options(seed=-1))
    with pytest.raises(SoilVolumeError, match="--bounds"):
        api.cloud_to_dem(pair[0], tmp_path / "d.tif", bounds=(1, 1, 0, 0))
    assert not any(tmp_path.glob("o*")) and not (tmp_path / "d.tif").exists()


def test_a_grid_too_coarse_for_the_overlap_is_refused_with_advice(capsys, pair, tmp_path):
    code, err = cli(capsys, "estimate", *pair, "--out", tmp_path / "o", "--cell", "50", "--quiet")
    _one_line_error(code, err, "--cell", "at least 25", "smaller --cell")
    code, err = cli(capsys, "dem", pair[0], "--out", tmp_path / "d.tif", "--cell", "100")
    _one_line_error(code, err, "--cell", "at least 25")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["after.las", "before.las"]


# -------------------------------------------------------------------------- inputs read-only
def _pipeline(path: Path, *stages) -> Path:
    path.write_text(json.dumps({"pipeline": list(stages)}))
    return path


@pytest.mark.parametrize("target", ["before", "after", "after-symlink", "after-dotdot"])
def test_a_pipeline_writer_onto_an_input_is_refused(capsys, pair, tmp_path, target):
    b, a = pair
    name = {"before": str(b), "after": str(a), "after-dotdot": str(tmp_path / "sub" / ".." / a.name)}.get(target)
    if target == "after-symlink":
        (tmp_path / "link.las").symlink_to(a)
        name = str(tmp_path / "link.las")
    sums = _md5(b, a)
    pipe = _pipeline(
        tmp_path / "p.json", {"type": "readers.las", "filename": str(b)}, {"type": "writers.las", "filename": name}
    )
    code, err = cli(capsys, "estimate", b, a, "--out", tmp_path / "o", "--before-pipeline", pipe, "--quiet")
    _one_line_error(code, err, "inputs are read-only")
    assert _md5(b, a) == sums and not (tmp_path / "o").exists() and _hidden(tmp_path) == []


def test_pipeline_writers_go_into_the_output_and_nowhere_else(capsys, pair, tmp_path):
    b, a = pair
    work = tmp_path / "work"
    work.mkdir()
    outside = tmp_path / "outside.laz"
    pipe = _pipeline(
        work / "p.json",
        {"type": "readers.las", "filename": str(b)},
        {"type": "writers.las", "filename": "../escape.las"},
        {"type": "writers.las", "filename": str(outside)},
    )
    code, err = cli(capsys, "estimate", b, a, "--out", work / "o", "--before-pipeline", pipe, "--quiet")
    assert code == 0, err
    assert {"escape.las", "outside.laz", "report.json"} <= {p.name for p in (work / "o").iterdir()}
    assert not outside.exists() and not (tmp_path / "escape.las").exists()
    # the same writers in a failing run leave nothing anywhere
    code, err = cli(
        capsys, "estimate", b, a, "--out", work / "o2", "--before-pipeline", pipe, "--cell", "50", "--quiet"
    )
    assert code == 1 and not (work / "o2").exists() and not outside.exists() and _hidden(work) == []


@pytest.mark.parametrize(
    ("stage", "named"),
    [
        ({"type": "filters.voxelcenternearestneighbor", "cell": 1.0}, "stage 'filters.voxelcenternearestneighbor'"),
        ({"type": "filters.crop", "bounds": "([0, 1], [0, 1])"}, "option 'bounds' of filters.crop"),
    ],
)
def test_a_pipeline_stage_beyond_the_embedded_executor_says_it_needs_pdal(
    capsys, pair, tmp_path, monkeypatch, stage, named
):
    """Without the pdal bindings, a user's pipeline with a stage or option the embedded executor
    does not have is one line naming it and saying it needs PDAL; nothing written, inputs intact
    (before: filters.voxelcenternearestneighbor ran; 'not supported by the embedded executor')."""
    monkeypatch.setitem(sys.modules, "pdal", None)
    b, a = pair
    sums = _md5(b, a)
    pipe = _pipeline(tmp_path / "p.json", str(b), {"type": "writers.las", "filename": "early.las"}, stage)
    code, err = cli(capsys, "estimate", b, a, "--out", tmp_path / "o", "--before-pipeline", pipe, "--quiet")
    _one_line_error(code, err, f"pipeline {pipe}: {named} needs PDAL")
    assert _md5(b, a) == sums and not (tmp_path / "o").exists() and _hidden(tmp_path) == []


def test_a_writer_may_not_take_the_name_of_a_run_output(capsys, pair, tmp_path):
    pipe = _pipeline(tmp_path / "p.json", str(pair[0]), {"type": "writers.las", "filename": "report.json"})
    code, err = cli(capsys, "estimate", *pair, "--out", tmp_path / "o", "--before-pipeline", pipe, "--quiet")
    _one_line_error(code, err, "report.json", "rename it")


# ------------------------------------------------------------------------------- LAS headers
def _patched(tmp_path, name, at, fmt, value, version="1.4") -> Path:
    src = tmp_path / "src.las"
    header = laspy.LasHeader(point_format=6 if version == "1.4" else 1, version=version)
    header.add_crs(pyproj.CRS("EPSG:32654"))
    las = laspy.LasData(header)
    xyz = _cloud(20)
    las.x, las.y, las.z = xyz.T
    las.write(str(src))
    data = bytearray(src.read_bytes())
    struct.pack_into(fmt, data, at, value)
    out = tmp_path / name
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize(
    ("name", "at", "fmt", "value", "expect"),
    [
        ("vlrs.las", 100, "<I", 2**32 - 1, "VLR"),
        ("count.las", 247, "<Q", 2**63 - 1, "points"),
        ("fewer.las", 247, "<Q", 100, "the header says 100"),
        ("nanoffset.las", 155, "<d", math.nan, "finite"),
        ("nanbound.las", 179, "<d", math.nan, "finite"),
        ("infscale.las", 131, "<d", math.inf, "scale"),
        ("zeroscale.las", 139, "<d", 0.0, "scale"),
        ("evlrs.las", 243, "<I", 2**32 - 1, "EVLR"),
        ("offset.las", 96, "<I", 2**31, "point data offset"),
    ],
)
def test_a_broken_header_is_one_line_naming_the_file(capsys, tmp_path, name, at, fmt, value, expect):
    bad = _patched(tmp_path, name, at, fmt, value)
    code, err = cli(capsys, "dem", bad, "--out", tmp_path / "d.tif")
    _one_line_error(code, err, name, expect)


def test_a_scale_that_moves_points_out_of_the_header_bounds_is_refused(capsys, tmp_path):
    bad = _patched(tmp_path, "scale.las", 131, "<d", 0.0101)  # x scale 0.01 -> 0.0101
    code, err = cli(capsys, "dem", bad, "--out", tmp_path / "d.tif")
    _one_line_error(code, err, "scale.las", "bounds")


def test_a_corrupted_wkt_is_not_reported_as_no_crs(capsys, tmp_path):
    src = _patched(tmp_path, "wkt.las", 0, "<4s", b"LASF")
    data = src.read_bytes().replace(b"PROJCRS[", b"PROJCRX[", 1)
    src.write_bytes(data)
    code, err = cli(capsys, "dem", src, "--out", tmp_path / "d.tif")
    _one_line_error(code, err, "wkt.las", "CRS")
    assert "no CRS" not in err[0] and len(err[0]) < 300


def test_tiny_and_collinear_clouds_name_the_file(capsys, pair, tmp_path):
    three = tmp_path / "three.las"
    write_las(three, np.array([[500000.0, 3900000, 50], [500010, 3900000, 51], [500000, 3900010, 52]]), WKT)
    code, err = cli(capsys, "estimate", pair[0], three, "--out", tmp_path / "o", "--quiet")
    _one_line_error(code, err, "three.las", "too few points")
    line = tmp_path / "line.las"
    t = np.linspace(0, 60, 3000)
    write_las(line, np.c_[t + 500000, t + 3900000, 50 + 0 * t], WKT)
    code, err = cli(capsys, "estimate", line, pair[1], "--out", tmp_path / "o", "--quiet")
    _one_line_error(code, err, "line.las", "on a line")


def test_a_crs_flag_contradicting_the_header_is_refused(capsys, pair, tmp_path):
    code, err = cli(capsys, "estimate", *pair, "--out", tmp_path / "o", "--before-crs", "EPSG:32655", "--quiet")
    _one_line_error(code, err, "before.las", "--before-crs", "differs from the CRS in the header")


# --------------------------------------------------------------------------------- OS faults
def test_os_faults_are_one_line(capsys, pair, tmp_path):
    b, a = pair
    (tmp_path / "afile").write_text("x")
    cases = [
        (["estimate", b, a, "--out", "/dev/null/out"], "/dev/null"),
        (["estimate", b, a, "--out", tmp_path / ("x" * 300)], "too long"),
        (["estimate", b, a, "--out", "/proc/soilvolume-test/out"], "/proc"),
        (["pipeline", b, a, "--emit", tmp_path / "afile"], "not a folder"),
        (["demo", "--out", tmp_path / "afile"], "not a folder"),
        (["dem", b, "--out", tmp_path / "missing" / "d.tif"], "does not exist"),
        (["volume", b, a, "--out", tmp_path / "missing" / "d.tif"], "does not exist"),
    ]
    for args, expect in cases:
        code, err = cli(capsys, *args)
        _one_line_error(code, err, expect)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "after.las", "before.las"]


def test_pipeline_json_that_is_not_utf8_or_nested_too_deep(capsys, pair, tmp_path):
    (tmp_path / "bin.json").write_bytes(b'{"pipeline": ["\xff\xfe.las"]}')
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    for name, expect in (("bin.json", "not UTF-8"), ("deep.json", "nested too deeply")):
        code, err = cli(
            capsys, "estimate", *pair, "--out", tmp_path / "o", "--before-pipeline", tmp_path / name, "--quiet"
        )
        _one_line_error(code, err, name, expect)


def test_a_full_disk_is_named_and_nothing_is_left(pair, tmp_path, monkeypatch):
    from soilvolume.dem import geotiff

    def full(src, dst, length=0):
        dst.write(src.read(100))  # the half-written temporary file
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(geotiff.shutil, "copyfileobj", full)  # where a raster's bytes are written
    with pytest.raises(SoilVolumeError, match="d.tif: No space left on device"):
        api.cloud_to_dem(pair[0], tmp_path / "d.tif")
    with pytest.raises(SoilVolumeError, match=r"/o/dem_\w+\.tif: No space left on device"):
        api.estimate(*pair, tmp_path / "o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["after.las", "before.las"]


# ------------------------------------------------------------------------------ output sets
def _stage(out: OutputDir, names: dict[str, str]) -> None:
    for name, text in names.items():
        out.path(name).write_text(text)


def test_overwrite_swaps_the_whole_set_and_keeps_no_stale_file(tmp_path):
    final = tmp_path / "result"
    old = OutputDir(final, [], False)
    _stage(old, {"report.json": "old", "after_registered.laz": "old", "change_areas.geojson": "old"})
    old.commit()
    new = OutputDir(final, [], True)
    assert (final / "report.json").read_text() == "old"  # a reader sees the old set while the new one builds
    _stage(new, {"report.json": "new", "difference.tif": "new"})
    new.commit()
    assert sorted(p.name for p in final.iterdir()) == ["difference.tif", "report.json"]
    assert (final / "report.json").read_text() == "new" and _hidden(tmp_path) == []


def test_overwrite_never_replaces_a_folder_of_other_files_or_inputs(tmp_path):
    final = tmp_path / "project"
    final.mkdir()
    (final / "notes.docx").write_text("mine")
    with pytest.raises(SoilVolumeError, match="notes.docx"):
        OutputDir(final, [], True)
    (final / "notes.docx").unlink()
    (final / "zones.geojson").write_text("mine")  # a run writes change_areas.geojson, no other GeoJSON
    with pytest.raises(SoilVolumeError, match="zones.geojson"):
        OutputDir(final, [], True)
    (final / "zones.geojson").unlink()
    (final / "before.las").write_text("cloud")
    with pytest.raises(SoilVolumeError, match="contains the input"):
        OutputDir(final, [final / "before.las"], True)
    assert sorted(p.name for p in final.iterdir()) == ["before.las"] and _hidden(tmp_path) == []


@pytest.mark.parametrize("flock", [True, False], ids=["flock", "lock-folder"])
def test_two_runs_into_one_folder(tmp_path, monkeypatch, flock):
    """Two runs into one folder take turns (the second refused), with flock or, where it is
    missing (Windows), the lock folder, which never stays behind."""
    import soilvolume.core.siblings as siblings

    if not flock:
        monkeypatch.setattr(siblings, "fcntl", None)
    final = tmp_path / "result"
    first, second = OutputDir(final, [], False), OutputDir(final, [], False)
    _stage(first, {"report.json": "first"})
    _stage(second, {"report.json": "second"})
    first.commit()
    with pytest.raises(SoilVolumeError, match="another run"):
        second.commit()
    second.abort()
    assert (final / "report.json").read_text() == "first" and _hidden(tmp_path) == []


def test_stale_staging_of_a_dead_run_is_swept(tmp_path):
    final = tmp_path / "result"
    (tmp_path / ".result.soilvolume-staging-999999999-ab12").mkdir()
    (tmp_path / ".d.tif.soilvolume-staging-999999999-ab12.tif").write_text("x")
    sweep(final)
    sweep(tmp_path / "d.tif")
    assert _hidden(tmp_path) == []


def test_a_mount_point_is_filled_in_place_and_dead_runs_staging_inside_is_swept(tmp_path, monkeypatch):
    import soilvolume.core.outputs as outputs

    final = tmp_path / "mnt"
    final.mkdir()
    (final / ".soilvolume-staging-999999999-ab12").mkdir()  # a killed run's
    (final / "report.json").write_text("old")
    (final / "stale.tif").write_text("old")
    monkeypatch.setattr(outputs.os.path, "ismount", lambda p: Path(p) == final)
    out = OutputDir(final, [], True)
    assert out.stage.parent == final
    _stage(out, {"report.json": "new"})
    out.commit()
    assert [p.name for p in final.iterdir()] == ["report.json"] and _hidden(tmp_path) == []


def test_estimate_overwrite_end_to_end(capsys, pair, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "report.json").write_text("{}")
    (out / "after_registered.laz").write_text("stale")
    code, err = cli(capsys, "estimate", *pair, "--out", out, "--overwrite", "--quiet")
    assert code == 0, err
    assert not (out / "after_registered.laz").exists() and json.loads((out / "report.json").read_text())["grid"]
    assert _hidden(tmp_path) == []


def test_volume_with_bad_zones_writes_nothing(capsys, tmp_path):
    from soilvolume.core.types import GridSpec
    from soilvolume.dem.geotiff import write_grid

    grid = GridSpec(500000.0, 3900050.0, 1.0, 50, 50, crs_wkt=WKT)
    write_grid(tmp_path / "b.tif", np.zeros((50, 50)), grid)
    write_grid(tmp_path / "a.tif", np.ones((50, 50)), grid)
    (tmp_path / "bad.gpkg").write_text("not a geopackage")
    code, err = cli(
        capsys,
        "volume",
        tmp_path / "b.tif",
        tmp_path / "a.tif",
        "--out",
        tmp_path / "d.tif",
        "--zones",
        tmp_path / "bad.gpkg",
    )
    _one_line_error(code, err, "bad.gpkg")
    assert not (tmp_path / "d.tif").exists() and _hidden(tmp_path) == []


def test_open3d_imported_without_its_plotly_drawing():
    """The engine imports Open3D without Dash/Plotly (0.6 s it never uses); an explicit import of
    Open3D's Plotly module afterwards still gets the real one."""
    code = (
        "import sys\n"
        "from soilvolume.registration.o3d import to_pcd\n"
        "import numpy as np\n"
        "assert len(to_pcd(np.zeros((3, 3))).points) == 3\n"
        "assert 'dash' not in sys.modules\n"
        "import open3d.visualization.draw_plotly as d\n"
        "assert 'dash' in sys.modules and d.draw_plotly.__module__ == d.__name__\n"
    )
    done = run_python(code, timeout=120)
    assert done.returncode == 0, done.stderr


def test_without_flock_the_engine_imports_and_a_stale_lock_is_one_line(tmp_path):
    """Windows has no fcntl: the engine still imports; a lock folder left by a killed run ends
    the wait with a clear line, no hang."""
    import soilvolume.core.siblings as siblings

    assert run_python("import sys; sys.modules['fcntl'] = None; import soilvolume.core.outputs").returncode == 0
    (tmp_path / siblings.LOCK_DIR).mkdir()  # a lock left by a killed run: a clear line, no hang
    with pytest.raises(SoilVolumeError, match="soilvolume-lock: another soilvolume run"):
        with siblings._lock_folder(tmp_path, wait_s=0.2):
            pass


@pytest.mark.parametrize("quiet", [True, False])
def test_an_unread_future_of_the_event_loop_prints_nothing(quiet):
    """A Dask client's close that outran its timeout on a busy host left a future whose exception nobody read:
    asyncio printed "Future exception was never retrieved" after the run's one-line error (seen once in a CI run
    of test_hostile's full-disk case on threads:1). The command line hands asyncio's records to a null handler."""
    code = (
        "import asyncio, gc\n"
        "from soilvolume.core.nativelog import quiet_library_logs\n"
        f"if {quiet}: quiet_library_logs()\n"
        "loop = asyncio.new_event_loop()\n"
        "f = loop.create_future()\n"
        "f.set_exception(TimeoutError('Timeout'))\n"
        "del f\n"
        "gc.collect()\n"
    )
    err = run_python(code).stderr
    assert ("never retrieved" in err) is not quiet, err
