"""A surface as the reference (issue 21, item 3): a survey against a design DEM GeoTIFF.

The design is the seeded pair's before ground (its analytic terrain written as a GeoTIFF), the
survey the pair's after cloud (well georeferenced, 3 cm noise): the truth is the pair's exact
analytic integral."""

from __future__ import annotations

import json
import time
from dataclasses import replace

import numpy as np
import pytest
import rasterio
from conftest import run_cli
from designs import Pad, pad_truth, write_surface

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.synthetic import make_pair, write_pair

SEED = 3
CONFIG = SceneConfig(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), noise_m=0.03)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    folder = tmp_path_factory.mktemp("design")
    _, after, truth = write_pair(make_pair(SEED, CONFIG), folder)
    return folder, after, json.loads(truth.read_text())


def _run(design, after, out, **options):
    t0 = time.perf_counter()
    res = estimate(design, after, out, replace(Options(), **options))
    return res.report, time.perf_counter() - t0


def test_survey_against_design_within_2_percent(site, tmp_path):
    folder, after, truth = site
    design = write_surface(folder / "design.tif", SEED, CONFIG)
    report, seconds = _run(design, after, tmp_path / "out")
    v, u = report["volume_m3"], report["uncertainty_m3"]
    for key in ("net", "cut", "fill"):
        assert abs(v[key] - truth[key]) <= 0.02 * abs(truth[key]), (key, v[key], truth[key])
        assert abs(v[key] - truth[key]) <= u[key], (key, v[key], truth[key], u[key])  # the interval holds
    assert report["reference"]["kind"] == "surface"
    assert report["registration"]["kind"] == "none: the reference is a surface"
    assert report["correction"]["method"] == "none"  # the design is not the existing ground
    assert report["quality"]["verdict"] == "reliable", report["quality"]
    assert "agrees with the design" in report["quality"]["messages"][0]
    agree = report["reference"]["agreement"]
    assert abs(agree["median_m"]) < 0.01 and agree["cells"] > 1000
    assert report["coverage"]["compared_share"] > 0.99
    html = (tmp_path / "out" / "report.html").read_text()
    assert "above design" in html and "below design" in html and "Reference surface" in html
    # the design on the run's grid: its analytic heights at the cell centres (bilinear there)
    with rasterio.open(tmp_path / "out" / "dem_before.tif") as ds, rasterio.open(design) as src:
        grid_z, t = ds.read(1, masked=True), ds.transform
        rows, cols = np.nonzero(~grid_z.mask)
        x, y = t.c + t.a * (cols + 0.5), t.f + t.e * (rows + 0.5)
        expected = np.array([v[0] for v in src.sample(zip(x, y, strict=True))])
        assert ds.crs == src.crs
    assert np.abs(grid_z.data[rows, cols] - expected).max() < 1e-3
    print(
        f"net {v['net']:+.2f} ± {u['net']:.2f} (truth {truth['net']:+.2f}), cut {v['cut']:.2f} ± {u['cut']:.2f} "
        f"({truth['cut']:.2f}), fill {v['fill']:.2f} ± {u['fill']:.2f} ({truth['fill']:.2f}), {seconds:.2f} s"
    )


@pytest.mark.parametrize("pad", [Pad(), Pad(fx=0.65, fy=0.35, half_x=12.0, half_y=9.0, level=0.8)])
def test_survey_against_a_grading_plan(site, tmp_path, pad):
    """A plan that is not the existing ground: a graded pad with 1:2 side slopes, in cut and in fill."""
    folder, after, _ = site
    truth = pad_truth(SEED, CONFIG, pad, res=0.1)
    report, _ = _run(write_surface(folder / "pad.tif", SEED, CONFIG, pad=pad), after, tmp_path / "out")
    v, u = report["volume_m3"], report["uncertainty_m3"]
    for key in ("net", "cut", "fill"):
        assert abs(v[key] - truth[key]) <= 0.02 * abs(truth[key]), (key, v[key], truth[key])
        assert abs(v[key] - truth[key]) <= u[key], (key, v[key], truth[key], u[key])  # the interval holds
    assert report["quality"]["verdict"] == "reliable", report["quality"]
    print(
        f"pad {pad.level:+.1f} m: net {v['net']:+.2f} ± {u['net']:.2f} ({truth['net']:+.2f}), cut {v['cut']:.2f} "
        f"± {u['cut']:.2f} ({truth['cut']:.2f}), fill {v['fill']:.2f} ± {u['fill']:.2f} ({truth['fill']:.2f})"
    )


def test_offset_design_is_not_reliable(site, tmp_path):
    folder, after, _ = site
    design = write_surface(folder / "design_up.tif", SEED, CONFIG, offset_m=0.3)
    report, _ = _run(design, after, tmp_path / "out")
    q = report["quality"]
    assert q["verdict"] == "not reliable" and not q["trusted"]
    assert "offset from the design by -0.30 m" in q["messages"][0], q["messages"]
    assert abs(report["reference"]["agreement"]["median_m"] + 0.3) < 0.01


def test_reprojected_design_and_feet(site, tmp_path):
    """A design in another CRS (geographic) is warped onto the survey's grid; one in feet converted."""
    from rasterio.warp import calculate_default_transform, reproject

    folder, after, truth = site
    utm = write_surface(folder / "design_utm.tif", SEED, CONFIG, cell=1.0)
    geo = folder / "design_geo.tif"
    with rasterio.open(utm) as src:
        t, w, h = calculate_default_transform(src.crs, "EPSG:4326", src.width, src.height, *src.bounds)
        out = np.full((h, w), np.nan, "float32")
        reproject(
            src.read(1),
            out,
            src_transform=src.transform,
            src_crs=src.crs,
            dst_transform=t,
            dst_crs="EPSG:4326",
            src_nodata=np.nan,
            dst_nodata=np.nan,
        )
        profile = {**src.profile, "crs": "EPSG:4326", "transform": t, "width": w, "height": h}
        with rasterio.open(geo, "w", **profile) as d:
            d.write(out, 1)
    report, _ = _run(geo, after, tmp_path / "geo")
    assert abs(report["volume_m3"]["net"] - truth["net"]) <= 0.02 * truth["net"]
    assert report["reference"]["crs"] == "WGS 84" and report["grid"]["crs"].endswith("zone 54N")
    assert report["reference"]["uncertainty_m3"]["resampling"]["net"] > 0  # a warped design is not exact
    feet = write_surface(folder / "design_ft.tif", SEED, CONFIG, cell=1.0, unit="ft")
    metres, _ = _run(utm, after, tmp_path / "m")
    in_feet, _ = _run(feet, after, tmp_path / "ft")
    assert in_feet["volume_m3"]["net"] == pytest.approx(metres["volume_m3"]["net"], rel=1e-3)
    assert "ft" in in_feet["reference"]["vertical_unit"]


def test_design_uncertainty_widens_the_interval(site, tmp_path):
    folder, after, _ = site
    design = write_surface(folder / "design.tif", SEED, CONFIG)
    exact, _ = _run(design, after, tmp_path / "exact")
    given, _ = _run(design, after, tmp_path / "given", design_uncertainty=0.02)
    term = given["reference"]["uncertainty_m3"]["given"]["net"]
    assert term == pytest.approx(1.96 * 0.02 * given["volume_m3"]["area_m2"], rel=0.01)
    assert given["uncertainty_m3"]["net"] >= max(term, exact["uncertainty_m3"]["net"])


def _refused(tmp_path, design, after, expect, *extra):
    inputs = design.read_bytes(), after.read_bytes()
    out = tmp_path / "out"
    p = run_cli("estimate", design, after, "--out", out, "--quiet", *extra)
    msg = p.stderr.strip()
    assert p.returncode != 0 and msg.startswith("soilvolume: error:") and len(msg.splitlines()) == 1, msg
    assert str(design.name) in msg and expect in msg, msg
    assert not out.exists(), "a refused run wrote something"
    assert (design.read_bytes(), after.read_bytes()) == inputs


def test_bad_designs_are_refused(site, tmp_path):
    folder, after, _ = site
    bands = write_surface(folder / "bands.tif", SEED, CONFIG, cell=2.0, bands=3)
    _refused(tmp_path, bands, after, "single-band DEM; this raster has 3 bands")
    no_crs = write_surface(folder / "nocrs.tif", SEED, CONFIG, cell=2.0, crs=None)
    _refused(tmp_path, no_crs, after, "has no CRS; give --before-crs")
    own = write_surface(folder / "own.tif", SEED, CONFIG, cell=2.0)
    _refused(tmp_path, own, after, "differs from the raster's CRS", "--before-crs", "EPSG:32655")
    garbage = folder / "garbage.tif"
    garbage.write_bytes(b"II*\x00" + bytes(range(256)) * 4)
    _refused(tmp_path, garbage, after, "not a readable raster")
    far = write_surface(folder / "far.tif", SEED, CONFIG, cell=2.0, shift_xy=(5000.0, 0.0))
    _refused(tmp_path, far, after, "does not overlap")
    p = run_cli("estimate", no_crs, after, "--out", tmp_path / "given", "--quiet", "--before-crs", "EPSG:32654")
    assert p.returncode == 0, p.stderr
    assert "below design" in p.stdout


def test_a_rerun_with_overwrite_replaces_the_outputs(site, tmp_path):
    """change_areas.geojson is a run's output too: a rerun with --overwrite replaces the folder."""
    folder, after, _ = site
    design = write_surface(folder / "design2.tif", SEED, CONFIG, cell=2.0)
    for extra in ((), ("--overwrite",)):
        p = run_cli("estimate", design, after, "--out", tmp_path / "out", "--quiet", *extra)
        assert p.returncode == 0, p.stderr
    assert (tmp_path / "out" / "change_areas.geojson").is_file()
