"""Contours of the difference and of each DEM (issue 54, item 4): ``--contour-interval`` writes
contours.gpkg by GDAL's contour algorithm. On a cone (height 9.9 - 0.5 r on a 0.3 m plinth: no level
falls on its apex or its flat foot) the contour at level L is the circle of radius (9.9 - L) / 0.5:
its vertices lie within a cell of it and its length is 2 pi r."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyogrio
import pytest
import rasterio
import shapely
from conftest import run_cli
from pyogrio.raw import read
from rasterio.transform import Affine

import soilvolume.workflow.steps as stepsmod
from soilvolume.api import estimate
from soilvolume.core.types import SoilVolumeError
from soilvolume.options import Options
from soilvolume.reporting import contours
from soilvolume.reporting.contours import FILE, write_contours

N, CELL, X0, Y0, BLANK = 101, 0.5, 500000.0, 3900000.0, 20  # BLANK: rows of nodata atop the difference
CX, CY = X0 + N * CELL / 2, Y0 + N * CELL / 2


def write_cone(folder: Path) -> Path:
    """dem_before flat at 100 m, dem_after a cone of 10 m on it, the difference the cone with its
    top BLANK rows nodata (EPSG:32654, 0.5 m cells, nodata -9999 as the run's rasters)."""
    col, row = np.meshgrid(np.arange(N), np.arange(N))
    r = np.hypot(X0 + (col + 0.5) * CELL - CX, Y0 + (N - row - 0.5) * CELL - CY)
    cone = np.maximum(9.9 - 0.5 * r, 0.3)
    diff = cone.copy()
    diff[:BLANK] = np.nan
    for name, a in (("difference", diff), ("dem_before", np.full_like(cone, 100.0)), ("dem_after", cone + 100.0)):
        profile = dict(driver="GTiff", width=N, height=N, count=1, dtype="float32", crs="EPSG:32654", nodata=-9999.0)
        transform = Affine(CELL, 0.0, X0, 0.0, -CELL, Y0 + N * CELL)
        with rasterio.open(folder / f"{name}.tif", "w", transform=transform, **profile) as dst:
            dst.write(np.where(np.isfinite(a), a, -9999.0).astype("float32"), 1)
    return folder


@pytest.fixture(params=["osgeo", "capi"])
def backend(request, monkeypatch):
    """Both ways to GDAL's contours: its Python bindings, and its C function by ctypes in
    rasterio's GDAL (the pip-installed engine has no bindings)."""
    if request.param == "osgeo":
        pytest.importorskip("osgeo.gdal")
    else:
        monkeypatch.setattr(contours, "_osgeo", lambda: None)
    return request.param


def lines(path: Path, layer: str) -> list[tuple[float, shapely.LineString]]:
    """(ELEV, line) of every feature of ``layer``."""
    _meta, _fids, geoms, fields = read(path, layer=layer)
    meta = pyogrio.read_info(path, layer=layer)
    elev = fields[list(meta["fields"]).index("ELEV")]
    return [(float(e), shapely.from_wkb(g)) for e, g in zip(elev, geoms, strict=True)]


def test_cone_contours_are_circles_of_known_radius(tmp_path, backend):
    folder = write_cone(tmp_path)
    summary = write_contours(folder / FILE, folder, 2.0)
    assert summary["lines"] == {"difference": 4, "dem_before": 0, "dem_after": 4}, summary
    assert [name for name, _kind in pyogrio.list_layers(folder / FILE)] == ["difference", "dem_before", "dem_after"]
    found = {}
    for level, line in lines(folder / FILE, "dem_after"):
        radius = (109.9 - level) / 0.5
        xy = shapely.get_coordinates(line)
        dist = np.hypot(xy[:, 0] - CX, xy[:, 1] - CY)
        assert np.abs(dist - radius).max() < 0.1 * CELL, (level, dist.min(), dist.max())  # measured <= 5 mm
        assert line.length == pytest.approx(2 * math.pi * radius, rel=0.005)  # measured <= 0.1 %
        assert line.is_closed
        found[level] = round(line.length, 2)
    assert sorted(found) == [102.0, 104.0, 106.0, 108.0], found


def test_no_contour_where_the_difference_is_nodata(tmp_path, backend):
    """The difference's circles stop at the nodata rows (GDAL told the rasters' nodata); its
    ELEV is metres of change, its ``change`` says fill above 0."""
    folder = write_cone(tmp_path)
    write_contours(folder / FILE, folder, 2.0)
    edge = Y0 + (N - BLANK) * CELL  # the top of the first valid row
    diff = lines(folder / FILE, "difference")
    tops = [shapely.get_coordinates(line)[:, 1].max() for _level, line in diff]
    assert max(tops) <= edge + 1e-6, (max(tops), edge)
    cut_off = [line for level, line in diff if level == 2.0][0]  # radius 15.8 m reaches past the edge
    assert not cut_off.is_closed and cut_off.length < 0.95 * 2 * math.pi * 15.8
    _meta, _fids, _geoms, fields = read(folder / FILE, layer="difference")
    assert set(fields[2]) == {"fill"} and sorted(fields[1]) == [2.0, 4.0, 6.0, 8.0]


def test_interval_must_be_positive(tmp_path):
    with pytest.raises(SoilVolumeError, match="contour interval"):
        write_contours(tmp_path / FILE, tmp_path, 0.0)
    assert not (tmp_path / FILE).exists()


@pytest.fixture(scope="module")
def contour_run(misaligned_result, misaligned_pair, tmp_path_factory):
    before, after, _truth = misaligned_pair
    out = tmp_path_factory.mktemp("contours") / "result"
    return estimate(before, after, out, replace(Options(), contour_interval=0.25)), out


def test_estimate_writes_contours_in_the_rasters_crs(contour_run, misaligned_result):
    """contours.gpkg among the run's outputs, its layers in difference.tif's CRS, the cut and fill
    readable from ELEV's sign, and every volume the run without contours gives."""
    res, out = contour_run
    plain = misaligned_result[0]
    assert res.report["volume_m3"] == plain.report["volume_m3"]
    assert res.report["uncertainty_m3"] == plain.report["uncertainty_m3"]
    assert res.outputs["contours"] == out / FILE
    assert res.report["contours"]["interval_m"] == 0.25 and min(res.report["contours"]["lines"].values()) > 0
    with rasterio.open(out / "difference.tif") as src:
        crs = src.crs
    for name, _kind in pyogrio.list_layers(out / FILE):
        assert rasterio.crs.CRS.from_user_input(pyogrio.read_info(out / FILE, layer=name)["crs"]) == crs, name
    _meta, _fids, _geoms, fields = read(out / FILE, layer="difference")
    elev, change = fields[1], fields[2]
    assert (elev < 0).any() and (elev > 0).any()
    assert all((c == "cut") == (e < 0) and (c == "fill") == (e > 0) for e, c in zip(elev, change, strict=True))
    assert np.allclose(np.round(elev / 0.25), elev / 0.25)


def test_negative_interval_is_refused_in_one_line(misaligned_pair, tmp_path):
    before, after, _ = misaligned_pair
    out = tmp_path / "out"
    p = run_cli("estimate", before, after, "--out", out, "--contour-interval", "-1", "--quiet")
    msg = p.stderr.strip()
    assert p.returncode != 0 and len(msg.splitlines()) == 1 and "--contour-interval" in msg, msg
    assert not out.exists()


def test_nothing_is_written_when_the_contours_fail(misaligned_pair, tmp_path, monkeypatch):
    """A failure while writing the contours (here: after a partial file) leaves no output folder."""

    def fail(path, folder, interval):
        Path(path).write_bytes(b"partial")
        raise SoilVolumeError(f"{path}: cannot write (no space left on the device)")

    monkeypatch.setattr(stepsmod, "write_contours", fail)
    before, after, _ = misaligned_pair
    with pytest.raises(SoilVolumeError, match="no space"):
        estimate(before, after, tmp_path / "out", replace(Options(), contour_interval=1.0))
    assert not (tmp_path / "out").exists() and list(tmp_path.iterdir()) == []
