"""Design rasters as users have them (issues 45 and 46): heights stored with a band scale and
offset, nodata declared or left as absurd fills, and a design far larger than the site.

The design is the seeded pair's before ground 100 m above the datum (heights 155-164 m), the
survey the pair's after cloud: the same design in any storage must give the same volumes."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from conftest import run_cli, run_python
from designs import write_surface
from rasterio.windows import Window

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.synthetic import make_pair, write_pair

SEED = 3
CONFIG = SceneConfig(shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), noise_m=0.03, origin=(5e5, 3.9e6, 100.0))
SURVEY_CENTRE = (500_082.0, 3_900_075.0)  # of the after survey's 67 x 62.7 m
HUGE = 200_000  # cells a side of the sparse designs: 4e10 declared, 160 GB as float32


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """(folder, the after survey, the truth, the design's profile and its heights in centimetres)."""
    folder = tmp_path_factory.mktemp("design_rasters")
    _, after, truth = write_pair(make_pair(SEED, CONFIG), folder)
    with rasterio.open(write_surface(folder / "metres.tif", SEED, CONFIG)) as ds:
        profile, cm = ds.profile, np.round(ds.read(1).astype(np.float64) * 100)
    return folder, after, json.loads(truth.read_text()), profile, cm


def _write(path, profile, z, nodata=None, scale=1.0, offset=0.0):
    with rasterio.open(path, "w", **{**profile, "dtype": z.dtype.name, "nodata": nodata}) as ds:
        ds.write(z, 1)
        ds.scales, ds.offsets = (scale,), (offset,)
    return path


def _volumes(design, after, out) -> tuple[dict, dict]:
    report = estimate(design, after, out, Options()).report
    return report["volume_m3"], report["reference"]


def test_scale_and_offset_give_the_metres_volumes(site, tmp_path):
    """int16 centimetres above 100 m (scale 0.01, offset 100) are the design in metres: the
    volumes of the float64 metres exactly, of float32 metres to its rounding; before, the stored
    centimetres were taken as metres (a -67 million m³ cut)."""
    folder, after, truth, profile, cm = site
    raw = (cm - 10_000).astype(np.int16)
    stored = _write(folder / "cm.tif", profile, raw, nodata=-32768, scale=0.01, offset=100.0)
    metres = raw.astype(np.float64) * 0.01 + 100.0
    as_f64 = _write(folder / "m64.tif", profile, metres)
    as_f32 = _write(folder / "m32.tif", profile, metres.astype(np.float32))
    v, ref = _volumes(stored, after, tmp_path / "cm")
    v64, _ = _volumes(as_f64, after, tmp_path / "m64")
    v32, _ = _volumes(as_f32, after, tmp_path / "m32")
    assert v == v64, (v, v64)
    for key in ("net", "cut", "fill"):
        assert v[key] == pytest.approx(v32[key], rel=1e-5)
        assert abs(v[key] - truth[key]) <= 0.02 * abs(truth[key]), (key, v[key], truth[key])
    assert (ref["scale"], ref["offset"], ref["dtype"]) == (0.01, 100.0, "int16")


@pytest.mark.parametrize(
    "fill, nodata",
    [(1e30, None), (-3.4028235e38, None), (np.inf, None), (-9999.0, None), (-9999.0, -9999.0), (1e30, 1e30)],
)
def test_nodata_and_absurd_fills_are_masked(site, tmp_path, fill, nodata):
    """A 10 x 10 m patch over the pit and the ground around it is nodata (declared or not): the
    volumes of the design with that patch NaN exactly, and an undeclared fill said in the
    report; before, 1e30 cells gave a 1e32 m³ cut."""
    folder, after, _, profile, cm = site
    metres = cm * 0.01
    hole = metres.copy()
    hole[168:188, 126:146] = np.nan  # x 63-73 m, y 60-70 m of the site's before box: the pit
    filled = np.where(np.isnan(hole), fill, metres).astype(np.float32)
    expected, _ = _volumes(_write(folder / "hole.tif", profile, hole.astype(np.float32)), after, tmp_path / "h")
    v, ref = _volumes(_write(folder / "fill.tif", profile, filled, nodata), after, tmp_path / "f")
    assert v == expected, (fill, nodata, v, expected)
    masked = ref["masked_as_nodata"]
    if nodata is None:
        assert (
            len(masked) == 1
            and masked[0]["cells"] == 400
            and list(map(float, masked[0]["values"])) == [float(np.float32(fill))]
        )
    else:
        assert masked == []


def _huge(path, profile, z, pixel, centre):
    """A tiled, sparse design of HUGE x HUGE ``pixel`` cells (declared nodata) centred on ``centre``
    (x, y), holding ``z`` at the site's place (at its centre if the site's corner is not in it): a
    few MB on disk."""
    t = profile["transform"]
    west, north = centre[0] - HUGE // 2 * pixel, centre[1] + HUGE // 2 * pixel
    prof = {**profile, "width": HUGE, "height": HUGE, "nodata": -9999.0, "tiled": True, "blockxsize": 256}
    prof |= {"blockysize": 256, "sparse_ok": True, "bigtiff": "YES", "compress": "deflate"}
    prof["transform"] = rasterio.transform.from_origin(west, north, pixel, pixel)
    col, row = round((t.c - west) / pixel), round((north - t.f) / pixel)
    col, row = (col, row) if 0 <= min(col, row) and max(col, row) < HUGE - max(z.shape) else (HUGE // 2, HUGE // 2)
    with rasterio.open(path, "w", **prof) as ds:
        ds.write(z.astype(np.float32), 1, window=Window(col, row, z.shape[1], z.shape[0]))
    return path


PEAK = """
import json, resource
from soilvolume.api import estimate
report = estimate({design!r}, {after!r}, {out!r}).report
peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({{"volume_m3": report["volume_m3"], "peak_mb": peak_mb, "window": report["reference"].get("window")}}))
"""


def test_a_huge_sparse_design_is_read_over_the_site_only(site, tmp_path):
    """A 100 x 100 km design of 0.5 m cells (4e10 declared, the site's few in it): the site's
    window is read, in bounded memory (the process's peak RSS), with the volumes of the small
    design; before, a 160 GB read: "out of memory: use a larger --cell"."""
    folder, after, _, profile, cm = site
    small = _write(folder / "small.tif", profile, (cm * 0.01).astype(np.float32))
    huge = _huge(folder / "huge.tif", profile, cm * 0.01, 0.5, (profile["transform"].c, profile["transform"].f))
    assert huge.stat().st_size < 20e6
    runs = {}
    for name, design in (("huge", huge), ("small", small)):
        p = run_python(PEAK.format(design=str(design), after=str(after), out=str(tmp_path / name)), timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        runs[name] = json.loads(p.stdout.strip().splitlines()[-1])
    for key in ("net", "cut", "fill"):
        assert runs["huge"]["volume_m3"][key] == pytest.approx(runs["small"]["volume_m3"][key], rel=1e-9, abs=1e-9)
    window = runs["huge"]["window"]
    assert window["cols"] * window["rows"] < 200_000  # the site's 67 x 63 m and a margin, of 0.5 m cells
    assert runs["huge"]["peak_mb"] < runs["small"]["peak_mb"] + 100, runs
    print({name: round(r["peak_mb"]) for name, r in runs.items()}, window)


def test_a_design_too_fine_over_the_site_is_refused_in_one_line(site, tmp_path):
    """A 0.5 mm design over the site (1.7e10 cells in the site's window): refused in one line naming
    the design and the remedy, nothing written, inputs untouched; before, a generic out of memory."""
    folder, after, _, profile, cm = site
    fine = _huge(folder / "fine.tif", profile, cm[:4, :4] * 0.01, 0.0005, SURVEY_CENTRE)
    inputs = fine.read_bytes(), after.read_bytes()
    out = tmp_path / "out"
    p = run_cli("estimate", fine, after, "--out", out, "--quiet")
    msg = p.stderr.strip()
    assert p.returncode != 0 and msg.startswith("soilvolume: error:") and len(msg.splitlines()) == 1, msg
    assert str(fine) in msg and "too many to read" in msg and "gdalwarp -tr" in msg, msg
    assert not out.exists() and (fine.read_bytes(), after.read_bytes()) == inputs


def test_a_band_unit_contradicting_the_vertical_crs_is_refused(site, tmp_path):
    """Heights declared in feet by the band but metres by the vertical CRS: which one holds is
    not guessed."""
    folder, after, _, profile, cm = site
    path = _write(folder / "both.tif", {**profile, "crs": "EPSG:32654+5703"}, (cm * 0.01).astype(np.float32))
    with rasterio.open(path, "r+") as ds:
        ds.set_band_unit(1, "ft")
    p = run_cli("estimate", path, after, "--out", tmp_path / "out", "--quiet")
    msg = p.stderr.strip()
    assert p.returncode != 0 and len(msg.splitlines()) == 1 and str(path) in msg, msg
    assert "the band's unit (ft) contradicts its vertical CRS" in msg, msg
    assert not (tmp_path / "out").exists()


def test_a_design_with_an_offset_only_keeps_its_heights(site, tmp_path):
    """Scale 1 and an offset: the offset is added (heights stored relative to 150 m)."""
    folder, after, truth, profile, cm = site
    rel = (cm * 0.01 - 150.0).astype(np.float32)
    v, ref = _volumes(_write(folder / "rel.tif", profile, rel, offset=150.0), after, tmp_path / "rel")
    assert ref["offset"] == 150.0
    assert abs(v["net"] - truth["net"]) <= 0.02 * abs(truth["net"]), (v, truth)
