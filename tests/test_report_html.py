"""report.html: self-contained, renders in headless Chromium with the maps (PNG) and histogram (SVG), and
never imports matplotlib."""

from __future__ import annotations

import base64
import json
import math
import re
import shutil
import struct
import subprocess
import zlib
from html import unescape

import numpy as np
import pytest
from conftest import run_cli, run_python, write_scene

from soilvolume.core.types import GridSpec
from soilvolume.reporting.figures import PUOR, RDBU, colour_ramp, difference_map, hillshade
from soilvolume.reporting.html import render_html, write_html, zero_notes
from soilvolume.reporting.svgparts import block_mean, png_bytes

GRID = GridSpec(xmin=500000.0, ymax=3900100.0, cell=0.5, rows=160, cols=200, origin=(500000.0, 3900000.0, 0.0))
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def report() -> dict:
    return {
        "volume_m3": {"net": 1040.2, "cut": 12.5, "fill": 1052.7, "area_m2": 8000.0},
        "volume_uncompensated_m3": {"net": 1101.0, "cut": 3.1, "fill": 1104.1},
        "volume_thresholded_m3": {"net": 1041.0, "cut": 10.0, "fill": 1051.0},
        "uncertainty_m3": {"net": 6.3, "cut": 1.2, "fill": 6.1},
        "uncertainty": {"lod_m": 0.05, "sigma_m": 0.025, "range_m": 11.0, "confidence": 0.95},
        "registration": {
            "transform": np.eye(4).tolist(),
            "coarse": {"method": "fpfh", "fitness": 0.8, "rmse": 0.3, "accepted": False},
            "fine": {"method": "icp", "fitness": 0.97, "rmse": 0.031},
        },
        "grid": {"cell_m": 0.5, "rows": 160, "cols": 200, "crs": "WGS 84 / UTM zone 54N", "compared_area_m2": 8000.0},
        "inputs": {
            "before": {"path": "before <1>.las", "points": 2500000, "crs": "EPSG:32654"},
            "after": {"path": "after.laz", "points": 1500000},
        },
        "timings_s": {"read": 0.4, "register": 2.1},
        "correction": {
            "method": "surface",
            "params": {
                "terms": ["1", "x"],
                "coefficients": [0.05, 0.001],
                "residuals": {"mean": 0.0, "std": 0.02, "nmad": 0.019},
            },
        },
    }


def arrays() -> dict:
    y, x = np.mgrid[0 : GRID.rows, 0 : GRID.cols] * GRID.cell
    d = 3 * np.exp(-((x - 50) ** 2 + (y - 40) ** 2) / 100) - np.exp(-((x - 20) ** 2) / 20)
    d[:10, :30] = np.nan
    rng = np.random.default_rng(0)
    filled = np.zeros(d.shape, bool)
    filled[50:55, 60:70] = True
    return {
        "difference": d,
        "dem_after": 100 + d + 0.01 * x,
        "filled_mask": filled,
        "residual": np.where(np.abs(d) < 0.05, rng.normal(0, 0.02, d.shape), np.nan),
    }


def png_size(uri: str) -> tuple[int, int]:
    data = base64.b64decode(uri.split(",", 1)[1])
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_the_page_states_the_reports_facts():
    """The page (a Jinja2 template) words report.json's numbers: the headline, the volume table,
    the registration as rotation and shift, the inputs and the correction."""
    rep = report()
    rep["registration"]["transform_local"] = [[1, 0, 0, 2.5], [0, 1, 0, -1.25], [0, 0, 1, 0.5], [0, 0, 0, 1]]
    page = render_html(rep, arrays(), GRID, "2026-01-02 03:04 UTC")
    cells = [unescape(re.sub("<[^>]+>", "", c)).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", page)]
    assert "Net change <b>1,040.20 ± 6.30 m³</b> (cut 12.50 ± 1.20 m³, fill 1,052.70 ± 6.10 m³" in page
    assert "over 8,000 m²" in page and "Run on 2026-01-02 03:04 UTC with soilvolume unknown." in page
    headline = cells.index("areas of significant change (headline)")
    assert cells[headline : headline + 5] == ["areas of significant change (headline)"] + [
        "1,040.20 ± 6.30",
        "12.50 ± 1.20",
        "1,052.70 ± 6.10",
        "8,000.0",
    ]
    assert cells[cells.index("without the vertical correction") + 1] == "1,101.00"
    assert cells[cells.index("fine") : cells.index("fine") + 4] == ["fine", "icp", "0.970", "0.031"]
    shift = math.hypot(2.5, -1.25, 0.5)
    assert [f"{shift:,.3f}", "2.500", "-1.250", "0.500"] == cells[cells.index("0.000") + 3 : cells.index("0.000") + 7]
    assert cells[cells.index("before") : cells.index("before") + 3] == ["before", "before <1>.las", "2,500,000"]
    assert cells[cells.index("x") + 1] == "0.001" and "Method: <b>surface</b>" in page
    assert cells[cells.index("level of detection (m)") + 1] == "0.0500"


def test_a_seeded_run_pages_text_is_its_report_json(tmp_path):
    """report.html of a seeded run: its headline, volume table and quality verdict are report.json's."""
    out = tmp_path / "o"
    before, after, _ = write_scene(tmp_path, 0)
    done = run_cli("estimate", before, after, "--out", out)
    assert done.returncode == 0, done.stderr
    rep = json.loads((out / "report.json").read_text())
    page = (out / "report.html").read_text()
    text = unescape(re.sub(r"\s+", " ", re.sub("<[^>]+>", " ", page)))
    v, u = rep["volume_m3"], rep["uncertainty_m3"]
    assert f"Net change {v['net']:,.2f} ± {u['net']:,.2f} m³" in text, text[:400]
    assert f"cut {v['cut']:,.2f} ± {u['cut']:,.2f} m³, fill {v['fill']:,.2f} ± {u['fill']:,.2f} m³" in text
    assert f"Quality: {rep['quality']['verdict']}" in text
    assert all(unescape(m) in text for m in rep["quality"]["messages"])
    assert "Template" not in text and "{{" not in page and "{%" not in page


def test_html_is_self_contained_and_tolerant(tmp_path):
    path = write_html(report(), arrays(), GRID, tmp_path / "report.html")
    text = path.read_text()
    assert "http://" not in text and "https://" not in text and "<script" not in text
    imgs = dict(re.findall(r'<img id="([\w-]+)" alt="[^"]*" src="(data:image/png;base64,[^"]+)"', text))
    assert set(imgs) == {"difference-map", "residual-map"}
    for uri in imgs.values():
        w, h = png_size(uri)
        assert w > 300 and h > 200
    hist = re.search(r'<svg class=plot id="histogram".*?</svg>', text)[0]
    assert hist.count("<rect class=bar") >= 30 and "±LoD95 = 0.050 m" in hist
    assert 'id="difference-map-colour-bar"' in text and 'id="residual-map-colour-bar"' in text
    assert "1,040.20 ± 6.30" in text and "before &lt;1&gt;.las" in text
    minimal = write_html({}, {}, GRID, tmp_path / "empty.html").read_text()
    assert "Volumes" in minimal and "<img" not in minimal and "<svg" not in minimal
    nan = {"difference": np.full((3, 4), np.nan), "residual": None, "dem_after": np.zeros((2, 2))}
    assert "<img" not in write_html({"uncertainty": {"lod_m": "n/a"}}, nan, GRID, tmp_path / "nan.html").read_text()


def test_does_not_import_matplotlib():
    code = (
        "import sys, numpy as np; import soilvolume.reporting.html as r; "
        "from soilvolume.core.types import GridSpec; "
        "g = GridSpec(xmin=0.0, ymax=50.0, cell=0.5, rows=100, cols=100); "
        "d = np.random.default_rng(0).normal(size=(100, 100)); "
        "html = r.render_html({'uncertainty': {'lod_m': 0.1}}, {'difference': d, 'residual': d, "
        "'dem_after': d, 'filled_mask': d > 2}, g); "
        "assert '<img' in html and '<svg' in html; assert 'matplotlib' not in sys.modules, 'matplotlib'"
    )
    res = run_python(code)
    assert res.returncode == 0, res.stderr


def test_colour_ramp_ends_centre_and_nan():
    rgba = colour_ramp(np.array([0.0, 2.0, -2.0, 5.0, -5.0, np.nan, 1.0]), 2.0)
    assert rgba.dtype == np.uint8 and rgba.shape == (7, 4)
    assert tuple(rgba[0]) == (*RDBU[len(RDBU) // 2].astype(int), 255) == (247, 247, 247, 255)
    assert tuple(rgba[1, :3]) == tuple(rgba[3, :3]) == tuple(RDBU[-1].astype(int))  # +limit, beyond: blue end
    assert tuple(rgba[2, :3]) == tuple(rgba[4, :3]) == tuple(RDBU[0].astype(int))  # -limit, beyond: red end
    assert rgba[5, 3] == 0 and (rgba[[0, 1, 2, 3, 4, 6], 3] == 255).all()
    assert rgba[6, 2] > rgba[6, 0]  # +limit/2 is bluish
    assert tuple(colour_ramp(np.array([0.0]), 1.0, PUOR)[0, :3]) == tuple(PUOR[5].astype(int))


def test_png_encoder_round_trip():
    rgba = np.random.default_rng(1).integers(0, 256, (7, 5, 4), dtype=np.uint8)
    data = png_bytes(rgba)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">II", data[16:24]) == (5, 7)
    idat = data[8 + 25 + 8 : -12]  # after the signature, IHDR chunk and the IDAT header
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(7, 1 + 5 * 4)
    assert raw[0, 0] == 0 and (raw[1:, 0] == 2).all()  # the first row as it is, the others "Up"
    assert (np.cumsum(raw[:, 1:], axis=0, dtype=np.uint8).reshape(7, 5, 4) == rgba).all()
    image = pytest.importorskip("PIL.Image")
    import io

    assert (np.asarray(image.open(io.BytesIO(data)).convert("RGBA")) == rgba).all()


def test_block_mean_ignores_nan_and_keeps_partial_blocks():
    a = np.arange(35, dtype=float).reshape(5, 7)
    a[0, 0] = np.nan
    a[4:, 4:] = np.nan
    m = block_mean(a, 3)
    assert m.shape == (2, 3)
    assert m[0, 0] == np.nanmean(a[:3, :3]) and m[1, 2] == np.nanmean(a[3:, 6:])
    assert np.isfinite(m).all() and block_mean(a, 1) is a


def test_hillshade_lights_slopes_facing_the_north_west_sun():
    flat = hillshade(np.zeros((5, 5)), 1.0)
    y, x = np.mgrid[0:5, 0:5].astype(float)  # row index runs south
    facing_sun = hillshade(x + y, 1.0)  # rising to the south-east: faces north-west
    away = hillshade(-(x + y), 1.0)
    assert np.allclose(flat, np.sqrt(0.5)) and (facing_sun > flat).all() and (away < flat).all()


def test_big_rasters_are_downsampled_for_display():
    grid = GridSpec(xmin=0.0, ymax=1000.0, cell=0.5, rows=2000, cols=1200)
    d = np.random.default_rng(2).normal(size=(2000, 1200))
    fig = difference_map(d, grid, relief=d, filled_mask=d > 2)
    w, h = png_size(re.search(r'src="(data:image/png;base64,[^"]+)"', fig)[1])
    assert (w, h) == (400, 667)  # 3 x 3 block means: the long side at most 900 px
    assert "shown as 3 x 3 cell means" in fig


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed")
def test_renders_in_headless_chromium(tmp_path):
    path = write_html(report(), arrays(), GRID, tmp_path / "report.html")
    probe = tmp_path / "probe.html"  # the report plus a script that records rendered sizes
    probe.write_text(
        path.read_text().replace(
            "</body>",
            (
                "<script>window.addEventListener('load',()=>{"
                "const r=e=>{const b=e.getBoundingClientRect();return Math.round(b.width)+'x'+Math.round(b.height)};"
                "const out=Array.from(document.images).map(i=>'img:'+i.id+':'+i.naturalWidth+':'+r(i)+':'"
                "+r(i.nextElementSibling));"
                "document.querySelectorAll('svg.plot').forEach(s=>out.push('svg:'+s.id+':'"
                "+s.querySelectorAll('rect.bar').length+':'+r(s)));"
                "document.body.setAttribute('data-probe',out.join(';'))})</script></body>"
            ),
        )
    )
    flags = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=3000",
    ]
    dom = subprocess.run(flags + ["--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=60).stdout
    probed = [e.split(":") for e in re.search(r'data-probe="([^"]*)"', dom)[1].split(";")]
    imgs = {e[1]: (int(e[2]), e[3], e[4]) for e in probed if e[0] == "img"}
    svgs = {e[1]: (int(e[2]), *map(int, e[3].split("x"))) for e in probed if e[0] == "svg"}
    for ident in ("difference-map", "residual-map"):
        natural, shown, overlay = imgs[ident]
        width, height = map(int, shown.split("x"))
        assert natural > 300 and width > 500 and height > 300  # decoded, non-broken, visible
        assert overlay == shown  # scale bar and north arrow drawn over the whole map
        assert svgs[f"{ident}-colour-bar"][1] > 300
    bars, width, height = svgs["histogram"]
    assert bars >= 30 and width > 500 and height > 200
    shot = tmp_path / "shot.png"
    subprocess.run(
        flags + [f"--screenshot={shot}", "--window-size=1200,2000", path.as_uri()], capture_output=True, timeout=60
    )
    assert shot.exists()
    assert struct.unpack(">II", shot.read_bytes()[16:24]) == (1200, 2000)


def test_a_zero_cut_beside_lowered_cells_is_explained():
    """Headline cut 0 while cells are lowered beyond the level of detection: the note next to
    the headline counts them by the rule that left them out (border, patch too small, own LoD);
    no note when the headline cut is not 0 or no cell is lowered at all."""
    d = np.full((8, 8), 0.05)
    d[0, 3] = -1.2  # on the border of the compared area
    d[4, 4] = -0.9  # alone inside: a patch of 1
    d[2, 2:5] = -0.7  # 3 touching cells: an area, but this one's own LoD is raised (not in ``change``)
    change = np.zeros_like(d, dtype=bool)
    change[5:7, 5:7] = True
    report = {
        "volume_m3": {"net": 12.0, "cut": 0.0, "fill": 12.0},
        "volume_all_cells_m3": {"net": 9.5, "cut": 4.1, "fill": 13.6},
        "volume_thresholded_m3": {"cut": 3.2},
        "uncertainty_m3": {"lod_m": 0.5, "net": 3.0, "net_all_cells": 6.0},
    }
    notes = zero_notes(report, {"difference": d, "change": change})
    assert [word for word, _ in notes] == ["cut"]
    note = notes[0][1]
    assert "5 cells are lower than -0.50 m (down to -1.20 m on the map)" in note, note
    assert "1 on the border, 1 in patches of fewer than 3 such cells, 3 within their own cell" in note, note
    assert "cut is 4.10 m³" in note and "3.20 m³" in note and "net +12.00 ± 3.00" in note, note
    assert zero_notes({**report, "volume_m3": {"net": 10.0, "cut": 2.0, "fill": 12.0}}, {"difference": d}) == []
    flat = {**report, "volume_all_cells_m3": {"net": 13.6, "cut": 0.0, "fill": 13.6}}
    assert zero_notes(flat, {"difference": np.abs(d)}) == []

    page = render_html(report, {"difference": d, "change": change}, GridSpec(500000.0, 3900008.0, 1.0, 8, 8))
    assert page.index("Why cut reads") < page.index("<h2>Volumes")
