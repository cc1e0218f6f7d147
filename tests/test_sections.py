"""Cross-section profiles (``--sections``): sections.csv holds the written DEMs' and difference's
heights every half cell along each line, in the run's CRS whatever the lines file's; one SVG per
line; a bad lines file is one error naming it, nothing written."""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ET

import numpy as np
import pyproj
import pytest
import rasterio
import shapely
from pyogrio import raw
from shapely.geometry import LineString, Point

from soilvolume.api import estimate
from soilvolume.core.types import SoilVolumeError
from soilvolume.options import Options
from soilvolume.reporting.sections import stations

PILE = (500067.0, 3900087.0, 3.5, 8.5)  # the scene's first cone: x, y, height, radius
PIT = (500068.0, 3900061.0)


def _lines_file(path, geoms, names, crs="EPSG:32654", driver="GeoJSON"):
    raw.write(
        str(path),
        geometry=shapely.to_wkb(geoms),
        field_data=[np.array(names, dtype=object)],
        fields=["name"],
        driver=driver,
        crs=crs,
        geometry_type=geoms[0].geom_type,
    )
    return path


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    from conftest import write_scene

    b, a, _truth = write_scene(tmp_path_factory.mktemp("pair"), seed=0)
    return b, a


def _rows(out):
    with open(out / "sections.csv", newline="") as f:
        return list(csv.DictReader(f))


def _float(v: str) -> float:
    return float(v) if v else np.nan


def test_profiles_sample_the_written_rasters_every_half_cell(pair, tmp_path):
    x, y, height, radius = PILE
    lines = [LineString([(x - 20, y), (x + 20, y)]), LineString([(PIT[0], PIT[1] - 15), (PIT[0], PIT[1] + 15)])]
    path = _lines_file(tmp_path / "lines.geojson", lines, ["across pile A", "pit"])
    out = tmp_path / "out"
    report = estimate(*pair, out, Options(sections=str(path))).report
    cell = report["grid"]["cell_m"]
    rows = _rows(out)
    assert list(rows[0]) == ["line_id", "name", "chainage_m", "x", "y", "before", "after", "difference"]
    pile = [r for r in rows if r["name"] == "across pile A"]
    chain = np.array([float(r["chainage_m"]) for r in pile])
    assert chain[0] == 0 and chain[-1] == pytest.approx(40.0) and np.diff(chain)[:-1] == pytest.approx(cell / 2)
    xy = [(float(r["x"]), float(r["y"])) for r in rows]
    for col, tif in (("before", "dem_before.tif"), ("after", "dem_after.tif"), ("difference", "difference.tif")):
        with rasterio.open(out / tif) as ds:
            values = np.ma.vstack(list(ds.sample(xy, masked=True)))[:, 0]
        want = np.ma.filled(values.astype(float), np.nan)  # nodata: an empty value
        got = np.array([_float(r[col]) for r in rows])
        np.testing.assert_array_equal(got, want)
    rise = np.array([_float(r["after"]) - _float(r["before"]) for r in pile])
    assert np.nanmax(rise) == pytest.approx(height, abs=0.4)  # the cone's top, on the line
    assert report["sections"] == {
        "file": "sections.csv",
        "lines": 2,
        "pictures": ["sections/across_pile_A.svg", "sections/pit.svg"],
    }
    svg = ET.parse(out / "sections" / "across_pile_A.svg").getroot()
    texts = [t.text for t in svg.iter("{http://www.w3.org/2000/svg}text")]
    assert "chainage (m)" in texts and "height (m)" in texts and "across pile A" in texts
    fills = [p for p in svg.iter("{http://www.w3.org/2000/svg}polygon") if p.get("fill") == "#2471a3"]
    assert fills, "the pile is shaded as fill"
    pit = ET.parse(out / "sections" / "pit.svg").getroot()
    assert [p for p in pit.iter("{http://www.w3.org/2000/svg}polygon") if p.get("fill") == "#c0392b"], "cut shaded"


def test_a_line_in_another_crs_is_reprojected(pair, tmp_path):
    x, y, _h, _r = PILE
    to_geo = pyproj.Transformer.from_crs("EPSG:32654", "EPSG:4326", always_xy=True)
    ends = [to_geo.transform(x - 20, y), to_geo.transform(x + 20, y)]
    path = _lines_file(tmp_path / "lines.gpkg", [LineString(ends)], ["geo"], crs="EPSG:4326", driver="GPKG")
    out = tmp_path / "out"
    estimate(*pair, out, Options(sections=str(path)))
    rows = _rows(out)
    assert float(rows[0]["x"]) == pytest.approx(x - 20, abs=0.01) and float(rows[0]["y"]) == pytest.approx(y, abs=0.01)
    assert float(rows[-1]["chainage_m"]) == pytest.approx(40.0, abs=0.02)


@pytest.mark.parametrize("case", ["missing", "points", "outside"])
def test_a_bad_lines_file_is_one_error_naming_it(pair, tmp_path, case):
    path = tmp_path / "lines.geojson"
    if case == "points":
        _lines_file(path, [Point(PILE[:2])], ["p"])
    elif case == "outside":
        _lines_file(path, [LineString([(600000, 3900000), (600100, 3900000)])], ["far"])
    before = path.read_bytes() if path.exists() else None
    out = tmp_path / "out"
    with pytest.raises(SoilVolumeError) as err:
        estimate(*pair, out, Options(sections=str(path)))
    message = str(err.value)
    assert str(path) in message and len(message.splitlines()) == 1, message
    assert {"missing": "not found", "points": "no line features", "outside": "crosses"}[case] in message
    assert not out.exists()
    assert (path.read_bytes() if path.exists() else None) == before


def test_stations_run_on_across_parts():
    line = shapely.MultiLineString([[(0, 0), (3, 0)], [(10, 0), (10, 2)]])
    chain, xy = stations(line, 1.0)
    assert chain.tolist() == [0, 1, 2, 3, 3, 4, 5]
    assert xy[-1].tolist() == [10, 2]


def test_no_sections_without_the_option(misaligned_result):
    _res, _truth, out = misaligned_result
    assert not (out / "sections.csv").exists() and "sections" not in json.loads((out / "report.json").read_text())


def test_against_a_design_the_before_is_the_design(pair, tmp_path):
    """A survey against a surface: the first height column is the design, sampled from it."""
    from designs import write_surface

    from soilvolume.scenes.synthetic import SceneConfig

    design = write_surface(tmp_path / "design.tif", 0, SceneConfig.small())
    x, y, height, _r = PILE
    path = _lines_file(tmp_path / "lines.geojson", [LineString([(x - 20, y), (x + 20, y)])], ["A"])
    out = tmp_path / "out"
    estimate(design, pair[1], out, Options(sections=str(path)))
    rows = _rows(out)
    assert list(rows[0])[5:] == ["design", "after", "difference"]
    rise = np.array([_float(r["after"]) - _float(r["design"]) for r in rows])
    assert np.nanmax(rise) - np.nanmedian(rise) == pytest.approx(height, abs=0.4)  # the after survey is not registered
    svg = (out / "sections" / "A.svg").read_text()
    assert ">design</text>" in svg
