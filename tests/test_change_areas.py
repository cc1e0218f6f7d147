"""change_areas.geojson: the areas of significant change as polygons that hold the headline's cut
and fill (buffer cells count with their area whatever their sign), in the run's CRS, readable by
GDAL; and the patches split by the cut mask, not by each cell's sign."""

from __future__ import annotations

import json

import numpy as np
import pytest

from soilvolume.core.types import GridSpec
from soilvolume.reporting.vectors import features, patches


def test_polygons_hold_the_headline_volumes(misaligned_result):
    res, _truth, out = misaligned_result
    doc = json.loads((out / "change_areas.geojson").read_text())
    head = res.report["volume_m3"]
    props = [f["properties"] for f in doc["features"]]
    assert {p["kind"] for p in props} == {"cut", "fill"}
    for kind in ("cut", "fill"):
        mine = [p["volume_m3"] for p in props if p["kind"] == kind]
        assert sum(mine) == pytest.approx(head[kind], abs=1e-3 * len(mine) + 1e-6), kind
    assert sum(p["area_m2"] for p in props) == pytest.approx(head["area_m2"], abs=1e-3 * len(props))
    assert doc["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32654"


def test_gdal_reads_them_with_their_crs(misaligned_result):
    import pyogrio

    _res, _truth, out = misaligned_result
    info = pyogrio.read_info(out / "change_areas.geojson")
    assert info["geometry_type"] == "Polygon" and info["features"] > 0
    assert info["crs"] == "EPSG:32654"
    _meta, _index, _geometry, fields = pyogrio.raw.read(out / "change_areas.geojson")
    assert set(fields[list(_meta["fields"]).index("kind")]) == {"cut", "fill"}


def test_a_pile_keeps_its_negative_buffer_cells():
    """A fill area whose buffer holds a slightly negative cell: one fill polygon with the
    area's sum, no cut polygon made of the buffer cell."""
    diff = np.zeros((6, 6))
    diff[1:5, 1:5] = 1.0
    diff[1, 1] = -0.05  # a buffer cell below zero
    change = diff != 0
    labels, kinds = patches(change, np.zeros_like(change))
    assert kinds == [("fill", 1)] and (labels > 0).sum() == 16
    grid = GridSpec(500000.0, 3900006.0, 1.0, 6, 6)
    (feature,) = features(diff, change, np.zeros_like(change), grid)
    assert feature["properties"]["volume_m3"] == pytest.approx(15 - 0.05)
    assert feature["properties"]["area_m2"] == 16


def test_a_refilled_patch_joins_the_area_around_it_not_one_at_its_corner():
    """A hole inside a pit joins its cut area; a large refilled patch (vegetation left out) at a
    few millimetres below zero that touches a small cut area at one corner does not."""
    from soilvolume.volumes.change import change_areas

    diff = np.zeros((30, 30))
    diff[3:9, 3:9] = -0.5  # a pit
    refilled = np.zeros_like(diff, bool)
    refilled[5:7, 5:7] = True  # a hole in it, filled at the pit's depth
    diff[12:14, 12:15] = -0.05  # a small cut
    refilled[14:26, 15:27] = True  # vegetation refilled, touching it at a corner
    diff[14:26, 15:27] = -0.015
    _, cut = change_areas(diff, 0.008, refilled=refilled)
    assert cut[5:7, 5:7].all() and cut[12:14, 12:15].all()
    assert not cut[16:26, 17:27].any()
