"""The tiled run's COGs: a small raster staged in memory gives the very file a large one's route
(blocks staged on disk) gives, a COG with overviews where it is large enough, and leaves nothing
else in the output folder."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio

from soilvolume.dem import geotiff
from soilvolume.dem.grid import make_grid


@pytest.mark.parametrize("shape", [(126, 135), (700, 300)])
def test_a_cog_staged_in_memory_is_the_one_staged_on_disk(tmp_path, monkeypatch, shape):
    grid = make_grid(np.zeros(2), np.array([shape[1], shape[0]]) * 0.37, 0.37, np.zeros(3), "EPSG:32617")
    rng = np.random.default_rng(0)
    heights = rng.normal(size=(grid.rows, grid.cols))
    heights[5:20, 7:30] = np.nan
    mask = (rng.random((grid.rows, grid.cols)) < 0.3).astype("uint8")
    files = {}
    for route, cells in (("memory", geotiff.IN_MEMORY_CELLS), ("disk", 0)):
        monkeypatch.setattr(geotiff, "IN_MEMORY_CELLS", cells)
        folder = tmp_path / route
        folder.mkdir()
        height, flags = geotiff.grid_layout(grid, "height", "metre"), geotiff.grid_layout(grid, "mask", "", "uint8")
        f = geotiff.write_cog(folder / "h.tif", height, lambda r, c: heights[r, c])
        m = geotiff.write_cog(folder / "m.tif", flags, lambda r, c: mask[r, c])
        assert sorted(p.name for p in folder.iterdir()) == ["h.tif", "m.tif"]
        files[route] = (f.read_bytes(), m.read_bytes())
    assert files["memory"] == files["disk"]
    with rasterio.open(tmp_path / "memory" / "h.tif") as ds:
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG" and ds.units == ("metre",)
        assert (len(ds.overviews(1)) > 0) == (max(shape) > geotiff.BLOCK)
        got = ds.read(1, masked=True)
        assert np.array_equal(got.mask, np.isnan(heights))
        assert np.array_equal(got.filled(0), np.where(np.isnan(heights), 0, heights.astype("float32")))
