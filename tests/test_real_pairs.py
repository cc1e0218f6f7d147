"""The two real two-epoch LiDAR pairs in ../shared/data/real, end to end through the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from conftest import run_cli


@pytest.fixture(scope="module")
def autzen(real_dir, tmp_path_factory):
    """Autzen BMX track, z in US survey feet (EPSG:2991+6360). Both epochs are professionally
    georeferenced airborne LiDAR and the 35 m x 42 m crop is almost all reshaped track: there is
    no stable ground to register on, so registration and correction would absorb the real
    change; a surveyor trusts the LiDAR georeferencing here (--fine none, --correction none)."""
    out = tmp_path_factory.mktemp("autzen") / "out"
    p = run_cli(
        "estimate",
        real_dir / "autzen_bmx_2010.las",
        real_dir / "autzen_bmx_2023.las",
        "--out",
        out,
        "--quiet",
        "--coarse",
        "none",
        "--fine",
        "none",
        "--correction",
        "none",
    )
    assert p.returncode == 0, p.stderr
    return json.loads((out / "report.json").read_text()), out


def test_autzen_net_is_positive_cubic_metres(autzen):
    """The mound was raised: the README's crude 3 m DoD gives about +469 m3 net (fill ~506 m3).
    Feet mistaken for metres would give 3.28x that; so the net must be positive and in range."""
    report, _ = autzen
    v = report["volume_m3"]
    assert v["net"] > 0
    assert 250 < v["net"] < 750, v
    assert v["fill"] > v["cut"]


def test_autzen_heights_are_metres(autzen):
    """NAVD88 heights of the track are 129-134 m (423-439 US survey ft in the files)."""
    _, out = autzen
    with rasterio.open(out / "dem_before.tif") as ds:
        z = ds.read(1, masked=True)
        assert "Oregon" in ds.crs.to_wkt() or ds.crs.to_epsg() == 2991
        assert ds.transform.a == pytest.approx(report_cell(out))
    assert 125 < float(z.min()) and float(z.max()) < 140


def report_cell(out) -> float:
    return json.loads((out / "report.json").read_text())["grid"]["cell_m"]


@pytest.fixture(scope="module")
def tommy(real_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("ttp") / "out"
    p = run_cli(
        "estimate",
        real_dir / "tommy_thompson_park_2015.laz",
        real_dir / "tommy_thompson_park_2023.laz",
        "--out",
        out,
        "--quiet",
    )
    assert p.returncode == 0, p.stderr
    return json.loads((out / "report.json").read_text()), out


def test_tommy_thompson_vertical_offset_removed(tommy):
    """Between 2015 and 2023 the ground of the whole park reads ~0.41 m lower (a datum or
    calibration difference, not soil loss; naive net about -58 000 m3). With default options,
    registration must lift the 2023 epoch by about that much, and the difference raster of the
    ground must then be centred on zero, with a net far smaller than the naive one."""
    report, out = tommy
    t = np.array(report["registration"]["transform_local"])
    assert 0.3 < t[2, 3] < 0.55, t[2, 3]
    with rasterio.open(out / "difference.tif") as ds:
        d = ds.read(1, masked=True).compressed()
    assert abs(float(np.median(d))) < 0.05
    assert abs(report["volume_m3"]["net"]) < 58_000 / 4
    assert report["registration"]["fine"]["fitness"] > 0.6
    assert report["inputs"]["before"]["selection"].startswith("class 2")
