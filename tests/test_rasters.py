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


def _raw(path, z, nodata=None, scale=1.0, offset=0.0, crs="EPSG:32654", transform=None, **creation):
    """A DEM of stored values ``z`` (their dtype) with a band scale and offset."""
    transform = transform or from_origin(500000, 3900100, 1.0, 1.0)
    profile = dict(driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype=z.dtype.name, crs=crs)
    with rasterio.open(path, "w", transform=transform, nodata=nodata, **profile, **creation) as ds:
        ds.write(z, 1)
        ds.scales, ds.offsets = (scale,), (offset,)
    return path


def test_scaled_dem_and_undeclared_fills(dems, tmp_path):
    """Before in int16 centimetres (scale 0.01, nodata -32768), after with ten cells of an
    undeclared 1e30: the known 200 m³ fill and 50 m³ cut over the cells both have; before, the
    centimetres were metres and the 1e30 cells heights."""
    zb = np.full((50, 60), 1000, np.int16)
    zb[0, 0] = -32768
    za = np.full((50, 60), 10.0, np.float32)
    za[10:20, 10:20] += 2.0
    za[30:35, 40:50] -= 1.0
    za[45, :10] = 1e30
    before = _raw(tmp_path / "cm.tif", zb, nodata=-32768, scale=0.01)
    res = volume_from_rasters(before, _raw(tmp_path / "fills.tif", za), tmp_path / "d.tif")
    t = res["total"]
    assert (t["fill"], t["cut"], t["cells"]) == (pytest.approx(200), pytest.approx(50), 50 * 60 - 11)
    assert res["inputs"]["after"]["masked_as_nodata"][0]["cells"] == 10
    assert res["inputs"]["before"]["scale"] == 0.01
    with rasterio.open(tmp_path / "d.tif") as ds:
        d = ds.read(1, masked=True)
        assert d.mask[45, :10].all() and d[15, 15] == pytest.approx(2.0)


def test_declared_height_units(dems, tmp_path):
    """Before in centimetres by its band's unit: converted (before, 1000 cm were 1000 m); a unit
    not understood refused in one line naming the file (before, taken as metres); feet by the
    vertical CRS (NAVD88 US survey feet) converted, not mixed with the after's metres."""
    cm = _raw(tmp_path / "cm.tif", np.full((50, 60), 1000.0, np.float32))
    odd = _raw(tmp_path / "odd.tif", np.full((50, 60), 10.0, np.float32))
    feet = _raw(tmp_path / "ft.tif", np.full((50, 60), 10.0 / 0.3048006096), crs="EPSG:32654+6360")
    for path, unit in ((cm, "cm"), (odd, "furlong")):
        with rasterio.open(path, "r+") as ds:
            ds.set_band_unit(1, unit)
    for before in (cm, feet):
        res = volume_from_rasters(before, dems[1], tmp_path / f"d_{before.stem}.tif")
        t = res["total"]
        assert t["fill"] == pytest.approx(200, rel=1e-6) and t["cut"] == pytest.approx(50, rel=1e-6), before
    assert "vertical CRS" in res["inputs"]["before"]["vertical_unit"]
    p = run_cli("volume", odd, dems[1], "--out", tmp_path / "d.tif")
    msg = p.stderr.strip()
    assert p.returncode != 0 and len(msg.splitlines()) == 1 and str(odd) in msg and "'furlong'" in msg, msg
    assert not (tmp_path / "d.tif").exists()


HUGE = 200_000  # cells a side of a sparse DEM: 4e10 declared, 160 GB as float32


def _huge(path, z, col, row):
    """A tiled, sparse DEM of HUGE x HUGE 1 m cells from 400000, 4000000 (nodata -9999), holding
    only ``z`` at cell ``col``, ``row``: a few MB on disk."""
    prof = dict(driver="GTiff", width=HUGE, height=HUGE, count=1, dtype="float32", crs="EPSG:32654", nodata=-9999)
    prof |= dict(tiled=True, blockxsize=256, blockysize=256, sparse_ok=True, bigtiff="YES")
    with rasterio.open(path, "w", transform=from_origin(400000, 4000000, 1.0, 1.0), **prof) as ds:
        ds.write(z.astype(np.float32), 1, window=rasterio.windows.Window(col, row, z.shape[1], z.shape[0]))
    return path


def test_a_huge_sparse_after_dem_is_read_over_the_before_only(dems, tmp_path):
    """An after DEM of 200 x 200 km (the site's 60 x 50 cells in it): read over the before's
    extent only; before, a 160 GB read (MemoryError)."""
    with rasterio.open(dems[1]) as src:
        huge = _huge(tmp_path / "huge.tif", src.read(1), 100000, 99900)  # at 500000, 3900100
    res = volume_from_rasters(dems[0], huge, tmp_path / "d.tif")
    t = res["total"]
    assert t["fill"] == pytest.approx(200) and t["cut"] == pytest.approx(50) and t["cells"] == 50 * 60 - 1


def test_a_huge_before_dem_is_refused_in_one_line(dems, tmp_path):
    """The before DEM is the difference's grid, read whole: 4e10 cells are refused in one line
    naming it and the remedy (crop or coarser), nothing written; before, "out of memory: use a
    larger --cell", an option the command does not have."""
    huge = _huge(tmp_path / "huge.tif", np.ones((1, 1)), 0, 0)
    inputs = huge.read_bytes(), dems[1].read_bytes()
    p = run_cli("volume", huge, dems[1], "--out", tmp_path / "d.tif")
    msg = p.stderr.strip()
    assert p.returncode != 0 and msg.startswith("soilvolume: error:") and len(msg.splitlines()) == 1, msg
    assert str(huge) in msg and "gdalwarp -te" in msg and "gdalwarp -tr" in msg, msg
    assert not (tmp_path / "d.tif").exists() and (huge.read_bytes(), dems[1].read_bytes()) == inputs


def test_huge_zone_coordinates_give_one_line_and_no_library_warning(dems, tmp_path):
    """Issue 49: shapely's 'RuntimeWarning: overflow encountered in area' reached the terminal
    before the one-line error; no library warning is shown unless asked (python -W)."""
    huge = [[[1e300, 1e300], [-1e300, 1e300], [-1e300, -1e300], [1e300, -1e300], [1e300, 1e300]]]
    feat = {"type": "Feature", "properties": {"name": "z"}, "geometry": {"type": "Polygon", "coordinates": huge}}
    doc = {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "EPSG:32654"}},
        "features": [feat],
    }
    zones = tmp_path / "huge.geojson"
    zones.write_text(json.dumps(doc))
    p = run_cli("volume", *dems, "--zones", zones, "--out", tmp_path / "d.tif")
    assert p.returncode == 1 and not (tmp_path / "d.tif").exists()
    assert p.stderr.splitlines() == [f"soilvolume: error: {zones}: no zone meets the survey's grid (is its CRS right?)"]
