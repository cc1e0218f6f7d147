"""The "Stockpile volumes" dialog on the QGIS desktop itself (``/usr/bin/qgis`` under Xvfb) as an
analyst uses it (issue 54): the plugin enabled in a clean profile, a seeded yard's LAS and its toe
polygons loaded in the project, the fields picked in the dialog, Run; ``stockpile_session.py``
run inside QGIS with ``--code``."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
import shapely
from pyogrio import raw

from soilvolume.scenes.yards import stockpile_yard

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
QGIS = shutil.which("qgis")
EAST, NORTH = 500_000.0, 4_000_000.0  # where the yard's local frame lies in UTM 33N
CRS = pyproj.CRS.from_epsg(32633)
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(QGIS is None or shutil.which("xvfb-run") is None, reason="needs QGIS's desktop and xvfb-run"),
]


def write_yard(folder: Path):
    """Seed 0's yard (one level pile, one on the slope) as yard.las and its toe polygons as
    piles.gpkg with a ``label`` and a ``rho`` (t/m³) field."""
    yard = stockpile_yard(0, columns=1, rows=1)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([EAST, NORTH, 0.0])
    header.add_crs(CRS)
    las = laspy.LasData(header)
    las.x, las.y, las.z = yard.x + EAST, yard.y + NORTH, yard.z
    las.write(str(folder / "yard.las"))
    polygons = [shapely.transform(p.polygon, lambda xy: xy + np.array([EAST, NORTH])) for p in yard.piles]
    fields = [np.array([p.name for p in yard.piles], dtype=object), np.array([p.density for p in yard.piles])]
    kw = {"fields": ["label", "rho"], "driver": "GPKG", "geometry_type": "Polygon", "crs": CRS.to_wkt()}
    raw.write(str(folder / "piles.gpkg"), shapely.to_wkb(polygons), field_data=fields, layer="piles", **kw)
    return yard


@pytest.fixture(scope="module")
def desktop(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("stockpile_desktop")
    plugins = root / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    (plugins / "soilvolume_qgis").symlink_to(REPO, target_is_directory=True)
    settings = root / "profiles" / "default" / "QGIS" / "QGIS3.ini"
    settings.parent.mkdir(parents=True)
    settings.write_text("[PythonPlugins]\nsoilvolume_qgis=true\n", encoding="utf-8")
    for folder in ("out", "home", "scene"):
        (root / folder).mkdir()
    yard = write_yard(root / "scene")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "QGIS_", "QT_", "VIRTUAL_ENV"))}
    env.update(HOME=str(root / "home"), SOILVOLUME_ANALYST_OUT=str(root / "out"))
    env.update(SOILVOLUME_ANALYST_SCENE=str(root / "scene"))
    env["SOILVOLUME_ENGINE_ENV"] = os.environ.get("SOILVOLUME_ENGINE_ENV", str(REPO / ".engine-env"))
    command = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", QGIS, "--profiles-path", str(root)]
    command += ["--nologo", "--noversioncheck", "--code", str(HERE / "stockpile_session.py")]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=900, cwd=str(root))
    summary_file, progress = root / "out" / "summary.json", root / "out" / "progress.log"
    assert summary_file.is_file(), done.stderr[-3000:] + (progress.read_text() if progress.is_file() else "")
    summary = json.loads(summary_file.read_text())
    assert summary.get("plugin_loaded") and "failure" not in summary, summary.get("failure")
    assert summary["python_errors"] == [], summary["python_errors"]
    return {"run": summary["run"], "out": root / "out" / "piles", "yard": yard}


def test_the_layer_fills_the_field_pickers(desktop):
    """The name combo lists the layer's fields, the density combo only its numeric one."""
    run = desktop["run"]
    assert run["layer_valid"], run
    assert "label" in run["offered"]["NAME_FIELD"] and "rho" in run["offered"]["NAME_FIELD"], run["offered"]
    assert "rho" in run["offered"]["DENSITY_FIELD"] and "label" not in run["offered"]["DENSITY_FIELD"], run["offered"]


def test_the_dialog_runs_to_the_truth_with_tonnes(desktop):
    """Each level pile within 1 % of its exact volume, named by the picked field; tonnes = volume x
    the picked density; the outputs written in the chosen folder."""
    run, yard = desktop["run"], desktop["yard"]
    assert run["ok"], run["log"][-2000:]
    assert run["results"]["PILES_COUNT"] == str(len(yard.piles)), run["results"]
    rows = {r["name"]: r for r in json.loads((desktop["out"] / "report.json").read_text())["piles"]}
    assert sorted(rows) == sorted(p.name for p in yard.piles), rows
    for p in yard.piles:
        if not p.on_slope:
            assert abs(rows[p.name]["volume_m3"] - p.volume_m3) / p.volume_m3 < 0.01, (p.name, rows[p.name])
        assert rows[p.name]["tonnes"] == pytest.approx(rows[p.name]["volume_m3"] * p.density, rel=1e-3)
    assert {f.name for f in desktop["out"].iterdir()} == {"report.json", "report.html", "piles.csv", "piles.gpkg"}


def test_the_report_is_listed_in_the_results_viewer(desktop):
    """As the estimate's: the report listed, the viewer open, the item named for the algorithm."""
    viewer = desktop["run"]["results_viewer"]
    assert str(desktop["out"] / "report.html") in viewer["listed"] and viewer["open"], viewer
    assert any(item.startswith("Stockpile volumes: report.html") for item in viewer["items"]), viewer
