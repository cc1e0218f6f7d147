"""LandXML TIN design surfaces as BEFORE (issue 54, item 3): the same design as a GeoTIFF gives
the same volumes; its units, its N/E order and its CRS honoured; its own triangles used; bad
files refused in one line with nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli
from designs import Pad, tin_of, write_landxml, write_surface

from soilvolume.api import estimate
from soilvolume.core.types import GridSpec, SoilVolumeError
from soilvolume.inputs import landxml
from soilvolume.options import Options
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.synthetic import make_pair, write_pair

SEED = 3
CONFIG = SceneConfig(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), noise_m=0.03, origin=(5e5, 3.9e6, 100.0))
PAD = Pad(fx=0.65, fy=0.35, half_x=12.0, half_y=9.0, level=0.8)
EPSG = 32654  # the scene's CRS


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """(folder, the after survey, the pad design as a GeoTIFF, its TIN (points, faces))."""
    folder = tmp_path_factory.mktemp("landxml")
    _, after, _ = write_pair(make_pair(SEED, CONFIG), folder)
    tif = write_surface(folder / "pad.tif", SEED, CONFIG, pad=PAD)
    return folder, after, tif, tin_of(tif)


def _volumes(design, after, out, **options) -> tuple[dict, dict]:
    report = estimate(design, after, out, Options(**options)).report
    return report["volume_m3"], report["reference"]


def test_a_landxml_design_gives_the_geotiff_designs_volumes(site, tmp_path):
    """The graded pad as a GeoTIFF and as a LandXML TIN of its pixel centres: cut, fill and net
    within 0.5 % (of cut + fill for the net)."""
    folder, after, tif, (points, faces) = site
    xml = write_landxml(folder / "pad.xml", points, faces, epsg=EPSG)
    v_tif, _ = _volumes(tif, after, tmp_path / "tif")
    v_xml, ref = _volumes(xml, after, tmp_path / "xml")
    print(f"GeoTIFF {v_tif}\nLandXML {v_xml}")
    for key in ("cut", "fill"):
        assert v_xml[key] == pytest.approx(v_tif[key], rel=0.005), (key, v_xml, v_tif)
    assert abs(v_xml["net"] - v_tif["net"]) <= 0.005 * (v_tif["cut"] + v_tif["fill"]), (v_xml, v_tif)
    assert ref["format"] == "LandXML TIN" and ref["surface"] == "design" and ref["triangles"] == len(faces)
    assert ref["crs"] == "WGS 84 / UTM zone 54N" and ref["path"] == str(xml)
    dem = json.loads((tmp_path / "xml" / "report.json").read_text())["inputs"]["before"]
    assert dem["linear_unit"] == "meter"


@pytest.mark.parametrize("unit", ["foot", "USSurveyFoot"])
def test_feet_are_converted_for_xy_and_heights(site, tmp_path, unit):
    """The same TIN written in feet (no namespace, the CRS given by --before-crs): the metre file's volumes."""
    folder, after, _, (points, faces) = site
    metres = write_landxml(folder / "m.xml", points, faces, epsg=EPSG)
    feet = write_landxml(folder / f"{unit}.landxml", points, faces, unit=unit, namespace="")
    v_m, _ = _volumes(metres, after, tmp_path / "m")
    v_ft, ref = _volumes(feet, after, tmp_path / "ft", before_crs=f"EPSG:{EPSG}")
    for key in ("net", "cut", "fill"):
        assert v_ft[key] == pytest.approx(v_m[key], rel=1e-4, abs=1e-3), (key, v_ft, v_m)
    assert ref["linear_unit"] == unit and unit in ref["vertical_unit"]


def test_the_files_crs_is_honoured_and_a_contradicting_before_crs_refused(site, tmp_path):
    """The TIN written in the next UTM zone (EPSG:32655, 500 km away in its coordinates): its
    points taken back into the survey's CRS, the metre file's volumes within 0.5 %; a
    --before-crs that contradicts the file's CRS is refused, nothing written."""
    import pyproj

    folder, after, _, (points, faces) = site
    x, y = pyproj.Transformer.from_crs(EPSG, 32655, always_xy=True).transform(points[:, 0], points[:, 1])
    other = write_landxml(folder / "z55.xml", np.c_[x, y, points[:, 2]], faces, epsg=32655)
    v_m, _ = _volumes(write_landxml(folder / "m.xml", points, faces, epsg=EPSG), after, tmp_path / "m")
    v_55, ref = _volumes(other, after, tmp_path / "z55")
    print(f"EPSG:{EPSG} {v_m}\nEPSG:32655 {v_55}")
    for key in ("cut", "fill"):
        assert v_55[key] == pytest.approx(v_m[key], rel=0.005), (key, v_55, v_m)
    assert ref["crs"] == "WGS 84 / UTM zone 55N"
    with pytest.raises(SoilVolumeError, match="differs from the LandXML file's CRS"):
        landxml.open_tin(other, f"EPSG:{EPSG}")


def test_points_are_northing_easting_and_the_files_triangles_are_used(tmp_path):
    """A plane z = 0.1 x + 0.02 y over two triangles of a 10 x 10 m square whose points are
    given N E Z: exact at every cell centre inside, NaN outside (the file's triangles cover only
    half the square a re-triangulation of the three-plus-one points would fill)."""
    corners = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    points = np.c_[corners, 0.1 * corners[:, 0] + 0.02 * corners[:, 1] + 50.0]
    path = write_landxml(tmp_path / "plane.xml", points, np.array([[0, 1, 2]]), epsg=EPSG)
    tin = landxml.open_tin(path, None)
    assert np.array_equal(tin.xy, corners) and np.allclose(tin.z, points[:, 2])
    grid = GridSpec(xmin=0.0, ymax=10.0, cell=1.0, rows=10, cols=10, crs_wkt=tin.crs.to_wkt())
    z = landxml.on_grid(tin, grid)
    x, y = np.meshgrid(np.arange(10) + 0.5, 9.5 - np.arange(10))
    inside = y <= x  # under the diagonal of the one triangle (0,0)-(10,0)-(10,10)
    assert np.allclose(z[inside], 0.1 * x[inside] + 0.02 * y[inside] + 50.0)
    assert np.isnan(z[~inside]).all()


BAD = {
    "no surface": ("<Surfaces/>", "no <Surface> in this LandXML file"),
    "no faces": (
        '<Surfaces><Surface name="s"><Definition surfType="TIN">{pnts}</Definition></Surface></Surfaces>',
        "the surface has no faces",
    ),
    "missing point": (
        '<Surfaces><Surface name="s"><Definition surfType="TIN">{pnts}<Faces><F>1 2 9</F></Faces></Definition>'
        "</Surface></Surfaces>",
        "a face names point '9', which is not in the surface's <Pnts>",
    ),
    "two-point face": (
        '<Surfaces><Surface name="s"><Definition surfType="TIN">{pnts}<Faces><F>1 2 3</F><F>1 2</F></Faces>'
        "</Definition></Surface></Surfaces>",
        "a face <F>1 2</F> does not name three points",
    ),
    "two-number point": (
        '<Surfaces><Surface name="s"><Definition surfType="TIN"><Pnts><P id="1">1 2</P></Pnts></Definition>'
        "</Surface></Surfaces>",
        "each <P> point must be three numbers 'northing easting elevation' (point '1': '1 2')",
    ),
    "not xml": ("<Surfaces><Surface", "cannot read it as LandXML"),
    "no crs": (
        '<Surfaces><Surface name="s"><Definition surfType="TIN">{pnts}<Faces><F>1 2 3</F></Faces></Definition>'
        "</Surface></Surfaces>",
        "the LandXML file declares no CRS",
    ),
}
PNTS = '<Pnts><P id="1">3900000 500000 150</P><P id="2">3900000 500100 150</P><P id="3">3900100 500100 150</P></Pnts>'


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_landxml_is_refused_in_one_line(site, tmp_path, case):
    _, after, _, _ = site
    body, expected = BAD[case]
    crs = "" if case == "no crs" else '<CoordinateSystem epsgCode="32654"/>'
    path = tmp_path / "bad.xml"
    path.write_text(
        f'<LandXML xmlns="http://www.landxml.org/schema/LandXML-1.2"><Units><Metric linearUnit="meter"/></Units>'
        f"{crs}{body.format(pnts=PNTS)}</LandXML>"
    )
    inputs = path.read_bytes(), after.read_bytes()
    out = tmp_path / "out"
    p = run_cli("estimate", path, after, "--out", out, "--quiet")
    msg = p.stderr.strip()
    assert p.returncode == 1 and len(msg.splitlines()) == 1, msg
    assert str(path) in msg and expected in msg, msg
    assert not out.exists() and (path.read_bytes(), after.read_bytes()) == inputs


def test_a_named_surface_is_chosen_and_an_unknown_name_refused(tmp_path):
    corners = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 1.0], [10.0, 10.0, 1.0]])
    path = write_landxml(tmp_path / "one.xml", corners, np.array([[0, 1, 2]]), epsg=EPSG, name="finished grade")
    assert landxml.open_tin(path, None, "finished grade").name == "finished grade"
    with pytest.raises(SoilVolumeError, match="no surface named 'subgrade' \\(it has: finished grade\\)"):
        landxml.open_tin(path, None, "subgrade")
