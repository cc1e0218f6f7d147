"""Point cloud to DEM, registration and volume from DEMs through processing.run."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from qgis.core import QgsRasterLayer


def test_point_cloud_to_dem(run_alg, scene_dir, tmp_path):
    out = tmp_path / "dem.tif"
    res = run_alg("pointcloudtodem", {"INPUT": str(scene_dir / "before.las"), "CELL": 2.0, "OUTPUT": str(out)})
    assert res["OUTPUT"] == str(out) and out.is_file()
    assert res["CELL_SIZE"] == pytest.approx(2.0)
    assert res["POINTS"] > 10_000 and 0 < res["VALID_CELLS"] <= res["ROWS"] * res["COLUMNS"]
    layer = QgsRasterLayer(str(out), "dem")
    try:
        assert layer.isValid() and layer.crs().authid() == "EPSG:32654"
        assert layer.width() == res["COLUMNS"] and layer.height() == res["ROWS"]
    finally:
        del layer
    with rasterio.open(out) as ds:
        assert ds.res == (2.0, 2.0)
        # the before survey covers ~158 m x 154 m
        assert ds.width * 2.0 == pytest.approx(158, abs=6) and ds.height * 2.0 == pytest.approx(154, abs=6)


def test_point_cloud_to_dem_on_an_extent(run_alg, scene_dir, tmp_path):
    out = tmp_path / "dem_extent.tif"
    extent = "500020,500060,3900030,3900070 [EPSG:32654]"
    res = run_alg(
        "pointcloudtodem", {"INPUT": str(scene_dir / "after.las"), "CELL": 1.0, "EXTENT": extent, "OUTPUT": str(out)}
    )
    with rasterio.open(out) as ds:
        assert ds.bounds.left == pytest.approx(500020, abs=1.0)
        assert ds.bounds.top == pytest.approx(3900070, abs=1.0)
        assert (ds.width, ds.height) == (res["COLUMNS"], res["ROWS"]) == (40, 40)


def test_register_point_clouds(run_alg, scene_dir, tmp_path, truth):
    import laspy

    out, matrix = tmp_path / "registered.laz", tmp_path / "transform.json"
    res = run_alg(
        "registerpointclouds",
        {
            "BEFORE": str(scene_dir / "before.las"),
            "AFTER": str(scene_dir / "after.las"),
            "OUTPUT": str(out),
            "TRANSFORM_FILE": str(matrix),
        },
    )
    estimated = np.array(json.loads(res["TRANSFORM"]))
    probe = np.array([500_079.0, 3_900_077.0, 60.0, 1.0])
    error = (estimated @ probe - np.array(truth["transform"]) @ probe)[:3]
    assert np.linalg.norm(error) < 0.1
    assert json.loads(matrix.read_text())["transform"] == json.loads(res["TRANSFORM"])
    assert 0 < res["FITNESS"] <= 1 and 0 <= res["RMSE"] < 1.0
    with laspy.open(out) as reader:
        assert reader.header.point_count > 10_000
        assert reader.header.parse_crs().to_epsg() == 32654
