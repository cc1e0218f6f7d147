"""Volume between two DEMs a user already has: totals, zones, resampling, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from conftest import run_cli
from rasterio.transform import from_origin

from soilvolume.api import volume_from_rasters
from soilvolume.core.types import SoilVolumeError


def _dem(path, z, transform=None, crs="EPSG:32654"):
    transform = transform or from_origin(500000, 3900100, 1.0, 1.0)
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=z.shape[1],
        height=z.shape[0],
        count=1,
        dtype="float32",
        crs=crs,
        transform=transform,
        nodata=-9999,
    ) as ds:
        ds.write(np.where(np.isfinite(z), z, -9999).astype("float32"), 1)
    return path


@pytest.fixture
def dems(tmp_path):
    zb = np.full((50, 60), 10.0)
    za = zb.copy()
    za[10:20, 10:20] += 2.0  # 100 cells x 2 m = 200 m3 fill
    za[30:35, 40:50] -= 1.0  # 50 cells x 1 m = 50 m3 cut
    za[0, 0] = np.nan
    return _dem(tmp_path / "b.tif", zb), _dem(tmp_path / "a.tif", za)


def test_totals_and_difference(dems, tmp_path):
    res = volume_from_rasters(*dems, tmp_path / "d.tif")
    t = res["total"]
    assert t["fill"] == pytest.approx(200) and t["cut"] == pytest.approx(50) and t["net"] == pytest.approx(150)
    assert t["cells"] == 50 * 60 - 1
    with rasterio.open(tmp_path / "d.tif") as ds:
        d = ds.read(1, masked=True)
        assert ds.crs.to_epsg() == 32654 and d.mask[0, 0] and d[15, 15] == pytest.approx(2.0)


def test_zones_sum_to_the_total(dems, tmp_path):
    zones = tmp_path / "zones.geojson"
    x0, y0 = 500000, 3900100

    def box(x1, y1, x2, y2):
        return [[[x0 + x1, y0 - y1], [x0 + x2, y0 - y1], [x0 + x2, y0 - y2], [x0 + x1, y0 - y2], [x0 + x1, y0 - y1]]]

    feats = [
        {"type": "Feature", "properties": {"name": n}, "geometry": {"type": "Polygon", "coordinates": c}}
        for n, c in (("west", box(0, 0, 30, 50)), ("east", box(30, 0, 60, 50)))
    ]
    zones.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": feats,
                "crs": {"type": "name", "properties": {"name": "EPSG:32654"}},
            }
        )
    )
    res = volume_from_rasters(*dems, tmp_path / "d.tif", zones=zones, zone_field="name")
    by = {z["name"]: z for z in res["zones"]}
    assert by["west"]["fill"] == pytest.approx(200) and by["east"]["cut"] == pytest.approx(50)
    assert sum(z["net"] for z in res["zones"]) == pytest.approx(res["total"]["net"])


def test_after_on_another_grid_is_resampled(dems, tmp_path):
    zb = np.full((50, 60), 10.0)
    shifted = _dem(tmp_path / "a2.tif", zb + 0.5, from_origin(500000.5, 3900100, 1.0, 1.0))
    res = volume_from_rasters(dems[0], shifted, tmp_path / "d.tif")
    assert res["total"]["net"] / res["total"]["area_m2"] == pytest.approx(0.5, abs=1e-6)


def test_no_overlap_and_missing_file(dems, tmp_path):
    far = _dem(tmp_path / "far.tif", np.ones((5, 5)), from_origin(600000, 3900100, 1.0, 1.0))
    with pytest.raises(SoilVolumeError, match="do not overlap"):
        volume_from_rasters(dems[0], far, tmp_path / "d.tif")
    with pytest.raises(SoilVolumeError, match="file not found"):
        volume_from_rasters(tmp_path / "none.tif", dems[1], tmp_path / "d.tif")


def test_cli_volume(dems, tmp_path):
    p = run_cli("volume", *dems, "--out", tmp_path / "d.tif")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["total"]["net"] == pytest.approx(150)
