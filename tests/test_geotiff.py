"""GeoTIFFs read back with rasterio: CRS, transform, nodata and cell values."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio

from soilvolume.api import cloud_to_dem
from soilvolume.dem.geotiff import NODATA
from soilvolume.dem.grid import average_height, make_grid
from soilvolume.inputs.io import read_points
from soilvolume.options import Options


def test_outputs_read_back(misaligned_result):
    res, _, out = misaligned_result
    g = res.report["grid"]
    for name in ("dem_before", "dem_after", "difference", "plane_offset"):
        with rasterio.open(out / f"{name}.tif") as ds:
            assert ds.crs.to_epsg() == 32654
            assert ds.nodata == NODATA
            assert (ds.height, ds.width) == (g["rows"], g["cols"])
            t = ds.transform
            assert t.a == pytest.approx(g["cell_m"]) and t.e == pytest.approx(-g["cell_m"])
            for edge in (t.c, t.f):  # cell edges on multiples of the cell size
                assert edge / g["cell_m"] == pytest.approx(round(edge / g["cell_m"]), abs=1e-6)
            band = ds.read(1, masked=True)
            assert band.count() > 0
    with (
        rasterio.open(out / "dem_before.tif") as b,
        rasterio.open(out / "dem_after.tif") as a,
        rasterio.open(out / "difference.tif") as d,
        rasterio.open(out / "plane_offset.tif") as o,
        rasterio.open(out / "filled_mask.tif") as f,
    ):
        hb, ha, dd, off = (x.read(1, masked=True).astype(float) for x in (b, a, d, o))
        filled = f.read(1) == 1
    assert filled.sum() < filled.size / 4  # interpolated cells (sparse or holes) are marked, few
    both = ~hb.mask & ~ha.mask & ~dd.mask & ~off.mask & ~filled
    assert np.abs((ha - hb - off)[both] - dd[both]).max() < 2e-3 + 0  # float32 storage
    assert d.nodata == NODATA
    # the sum of the difference raster is the net over every compared cell (the paper's sum)
    assert float(dd.sum()) * g["cell_m"] ** 2 == pytest.approx(res.report["volume_all_cells_m3"]["net"], rel=1e-3)
    assert 40 < float(hb.mean()) < 120  # metres above the datum, synthetic site


def test_dem_cells_equal_numpy_means(misaligned_pair, tmp_path):
    before, _, _ = misaligned_pair
    out = tmp_path / "dem.tif"
    info = cloud_to_dem(before, out, Options(cell=2.0, statistic="mean", ground="none"))
    xyz = read_points(before).xyz
    with rasterio.open(out) as ds:
        band = ds.read(1, masked=True)
        t = ds.transform
        assert ds.crs.to_epsg() == 32654 and info["cell_m"] == 2.0
        col = np.floor((xyz[:, 0] - t.c) / t.a).astype(int)
        row = np.floor((xyz[:, 1] - t.f) / t.e).astype(int)
        h = band.filled(np.nan)
        for r, c in [(5, 7), (20, 33), (40, 60)]:
            sel = (row == r) & (col == c)
            assert sel.any()
            # the mean of the cell's points, moved from their mean position to the cell centre
            # along the slope of the neighbouring cells
            dx = xyz[sel, 0].mean() - (t.c + (c + 0.5) * t.a)
            dy = xyz[sel, 1].mean() - (t.f + (r + 0.5) * t.e)
            gx = (h[r, c + 1] - h[r, c - 1]) / (2 * t.a)
            gy = (h[r - 1, c] - h[r + 1, c]) / (2 * t.a)
            assert band[r, c] == pytest.approx(xyz[sel, 2].mean() - gx * dx - gy * dy, abs=2e-3)


def test_robust_mean_ignores_an_outlier():
    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 1, 50), rng.uniform(0, 1, 50), rng.normal(10, 0.02, 50)]
    xyz[0, 2] = 25.0  # a floater
    grid = make_grid(np.zeros(3), np.ones(3), 1.0, np.zeros(3), None)
    mean, _ = average_height(xyz, grid, "mean")
    robust, n = average_height(xyz, grid, "robust-mean")
    assert n[0, 0] == 50
    assert abs(mean[0, 0] - 10) > 0.25
    assert robust[0, 0] == pytest.approx(xyz[1:, 2].mean(), abs=0.01)


def test_dem_of_a_geographic_cloud_is_in_its_utm_zone(tmp_path):
    """Lon/lat input: the DEM is written in the UTM zone of the cloud's position, in metres."""
    import pyproj

    from soilvolume.inputs.io import write_las

    rng = np.random.default_rng(3)
    n = 20_000
    lon = 139.70 + rng.uniform(0, 0.0005, n)  # ~45 m x 55 m in Tokyo: UTM zone 54N
    lat = 35.68 + rng.uniform(0, 0.0005, n)
    z = 40.0 + rng.normal(0, 0.01, n)
    write_las(tmp_path / "geo.laz", np.c_[lon, lat, z], pyproj.CRS("EPSG:4326").to_wkt(), scale=1e-7)
    info = cloud_to_dem(tmp_path / "geo.laz", tmp_path / "geo.tif", Options(cell=1.0))
    assert "UTM zone 54N" in info["crs"]
    with rasterio.open(tmp_path / "geo.tif") as ds:
        assert ds.crs.to_epsg() == 32654 and ds.res == (1.0, 1.0)
        assert 40 < ds.width < 50 and 50 < ds.height < 60
        h = ds.read(1, masked=True)
        assert abs(float(h.mean()) - 40.0) < 0.01
