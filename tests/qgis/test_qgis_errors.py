"""Bad parameters and missing dependencies give a QgsProcessingException with a clear message."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from qgis.core import QgsProcessingException


@pytest.fixture(scope="module")
def xyz_pair(scene_dir, tmp_path_factory) -> tuple[Path, Path]:
    """The scene's clouds as XYZ text files, which carry no CRS (every 4th point)."""
    import laspy

    folder = tmp_path_factory.mktemp("xyz")
    paths = []
    for name in ("before", "after"):
        las = laspy.read(scene_dir / f"{name}.las")
        path = folder / f"{name}.xyz"
        np.savetxt(path, np.c_[las.x, las.y, las.z][::4], fmt="%.3f")
        paths.append(path)
    return paths[0], paths[1]


def test_wrong_file_type(run_alg, scene_dir, tmp_path):
    shapefile = tmp_path / "parcels.shp"
    shapefile.write_bytes(b"\0" * 100)
    with pytest.raises(QgsProcessingException, match=r"unsupported file type '\.shp'"):
        run_alg(
            "estimatevolumechange",
            {"BEFORE": str(shapefile), "AFTER": str(scene_dir / "after.las"), "DIFFERENCE": str(tmp_path / "d.tif")},
        )


def test_missing_file(run_alg, scene_dir, tmp_path):
    with pytest.raises(QgsProcessingException, match="file not found"):
        run_alg(
            "registerpointclouds",
            {
                "BEFORE": str(tmp_path / "nowhere.las"),
                "AFTER": str(scene_dir / "after.las"),
                "OUTPUT": str(tmp_path / "r.laz"),
            },
        )


def test_no_input_cloud(run_alg, tmp_path):
    with pytest.raises(QgsProcessingException, match="No input point cloud"):
        run_alg("pointcloudtodem", {"OUTPUT": str(tmp_path / "dem.tif")})


def test_missing_crs_names_the_parameter(run_alg, xyz_pair, tmp_path):
    before, after = xyz_pair
    with pytest.raises(QgsProcessingException) as info:
        run_alg(
            "estimatevolumechange", {"BEFORE": str(before), "AFTER": str(after), "DIFFERENCE": str(tmp_path / "d.tif")}
        )
    message = str(info.value)
    assert "CRS" in message and "CRS override" in message
    assert not (tmp_path / "d.tif").exists()


def test_crs_override_makes_xyz_usable(run_alg, xyz_pair, tmp_path):
    res = run_alg(
        "pointcloudtodem",
        {"INPUT": str(xyz_pair[0]), "CRS": "EPSG:32654", "CELL": 4.0, "OUTPUT": str(tmp_path / "dem.tif")},
    )
    assert res["VALID_CELLS"] > 100


def test_no_overlap(run_alg, scene_dir, tmp_path):
    import laspy

    far = tmp_path / "far.las"
    las = laspy.read(scene_dir / "after.las")
    las.x = np.asarray(las.x) + 10_000.0  # 10 km east of the before survey
    las.write(far)
    with pytest.raises(QgsProcessingException) as info:
        run_alg(
            "estimatevolumechange",
            {"BEFORE": str(scene_dir / "before.las"), "AFTER": str(far), "DIFFERENCE": str(tmp_path / "d.tif")},
        )
    assert "overlap" in str(info.value).lower()
    assert not (tmp_path / "d.tif").exists()


def test_missing_environment_names_the_installer(run_alg, scene_dir, tmp_path, monkeypatch):
    """The error says the environment is missing and points to the warning, which says why and
    the three ways to install it (once: Processing repeats the error itself)."""
    from .recording import RecordingFeedback

    monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", str(tmp_path / "no-environment"))
    feedback = RecordingFeedback()
    with pytest.raises(QgsProcessingException) as info:
        run_alg(
            "estimatevolumechange",
            {
                "BEFORE": str(scene_dir / "before.las"),
                "AFTER": str(scene_dir / "after.las"),
                "DIFFERENCE": str(tmp_path / "d.tif"),
            },
            feedback=feedback,
        )
    assert "environment is missing" in str(info.value) and "warning above" in str(info.value)
    (advice,) = feedback.warnings
    assert "not installed yet" in advice and str(tmp_path / "no-environment") in advice
    assert "qgis_process run soilvolume:installdependencies" in advice and "Install dependencies" in advice
    assert not (tmp_path / "d.tif").exists()


def test_a_crashed_engine_gives_one_message_with_its_last_lines(run_alg, scene_dir, tmp_path, monkeypatch):
    """A child that dies (here by SIGSEGV after a line on stderr): one message naming the
    signal and the child's last lines; nothing written."""
    from soilvolume_qgis.plugin import environment

    crash = (
        "import os,signal,sys; print('engine: about to crash', file=sys.stderr, flush=True); "
        "os.kill(os.getpid(), signal.SIGSEGV)"
    )
    monkeypatch.setattr(environment.Environment, "command", lambda self, args: [sys.executable, "-c", crash])
    with pytest.raises(QgsProcessingException) as info:
        run_alg("pointcloudtodem", {"INPUT": str(scene_dir / "before.las"), "OUTPUT": str(tmp_path / "dem.tif")})
    message = str(info.value)
    assert "stopped unexpectedly (signal SIGSEGV)" in message and "engine: about to crash" in message
    assert not (tmp_path / "dem.tif").exists()


@pytest.mark.parametrize(
    ("alg", "extra", "expect"),
    [
        ("estimatevolumechange", {"LOD_CONFIDENCE": 1.5}, "Confidence level"),
        ("estimatevolumechange", {"CELL": 50.0}, "(CELL)"),
        ("estimatevolumechange", {"CELL": 1e9}, "Grid cell size"),
        ("pointcloudtodem", {"CELL": 500.0}, "(CELL)"),
        ("estimatevolumechange", {"SEED": -1}, "Random seed"),
    ],
)
def test_absurd_options_are_refused_naming_the_parameter(run_alg, scene_dir, tmp_path, alg, extra, expect):
    """Out of the table's range: refused by the parameter's own check; in range but too coarse for
    the site: refused by the engine with advice. Nothing is written either way."""
    if alg == "pointcloudtodem":
        params = {"INPUT": str(scene_dir / "before.las"), "OUTPUT": str(tmp_path / "dem.tif")}
    else:
        b, a = scene_dir / "before.las", scene_dir / "after.las"
        params = {"BEFORE": str(b), "AFTER": str(a), "DIFFERENCE": str(tmp_path / "d.tif")}
    with pytest.raises(QgsProcessingException) as info:
        run_alg(alg, {**params, **extra})
    assert expect in str(info.value), str(info.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_full_disk_while_delivering_leaves_no_half_written_output(plugin_package, tmp_path, monkeypatch):
    """Outputs are copied through a partial file renamed into place: a copy that fails half-way
    leaves neither the destination nor the partial file (and an earlier destination intact)."""
    import errno
    import shutil

    from soilvolume_qgis.processing import params

    src = tmp_path / "difference.tif"
    src.write_bytes(b"x" * 10_000)
    dest = tmp_path / "out" / "d.tif"
    dest.parent.mkdir()
    dest.write_bytes(b"the previous run")

    def half(a, b):
        Path(b).write_bytes(Path(a).read_bytes()[:5_000])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(shutil, "copyfile", half)
    with pytest.raises(QgsProcessingException, match=r"Cannot write .*d\.tif: No space left on device"):
        params.deliver_raster(src, str(dest))
    assert dest.read_bytes() == b"the previous run" and sorted(p.name for p in dest.parent.iterdir()) == ["d.tif"]


@pytest.mark.parametrize("link", ["same path", "hardlink"])
def test_one_survey_as_before_and_after_is_refused(run_alg, scene_dir, tmp_path, link):
    """The same file as both surveys (or a hard link to it) would give 0 ± 0 m³ and an empty layer:
    the engine refuses it, the message names the file; nothing is written."""
    import os

    before = scene_dir / "after.las"
    after = before if link == "same path" else tmp_path / "twin.las"
    if after != before:
        os.link(before, after)
    with pytest.raises(QgsProcessingException) as info:
        run_alg(
            "estimatevolumechange", {"BEFORE": str(before), "AFTER": str(after), "DIFFERENCE": str(tmp_path / "d.tif")}
        )
    assert f"{after}: is the same file as the before survey {before}" in str(info.value), str(info.value)
    assert not (tmp_path / "d.tif").exists()
    with pytest.raises(QgsProcessingException) as info:  # and as two epochs of a series
        run_alg("volumeseries", {"EPOCHS": [str(before), str(after)], "OUTPUT_FOLDER": str(tmp_path / "out")})
    assert f"E1 {after.name} " in str(info.value) and f"is the same file as E0 {before.name} " in str(info.value)
    assert not (tmp_path / "out").exists()


def test_an_output_folder_that_cannot_be_made_is_one_message_naming_it(run_alg, scene_dir, tmp_path):
    """The output's folder cannot be created (a file stands where it would be): one
    QgsProcessingException naming the output and the folder, before the engine runs."""
    blocker = tmp_path / "taken"
    blocker.write_text("a file, not a folder")
    out = blocker / "sub" / "dem.tif"
    with pytest.raises(QgsProcessingException) as info:
        run_alg("pointcloudtodem", {"INPUT": str(scene_dir / "after.las"), "OUTPUT": str(out)})
    assert f"Average-height DEM: cannot write into the folder {out.parent}: {blocker} is a file" in str(info.value)
    assert blocker.read_text() == "a file, not a folder" and sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
