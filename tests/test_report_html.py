"""report.html: self-contained, renders in headless Chromium with the map and histogram."""

from __future__ import annotations

import base64
import re
import shutil
import struct
import subprocess

import numpy as np
import pytest

from soilvolume.report_html import write_html
from soilvolume.types import GridSpec

GRID = GridSpec(xmin=500000.0, ymax=3900100.0, cell=0.5, rows=160, cols=200,
                origin=(500000.0, 3900000.0, 0.0))
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def report() -> dict:
    return {
        "volume_m3": {"net": 1040.2, "cut": 12.5, "fill": 1052.7, "area_m2": 8000.0},
        "volume_uncompensated_m3": {"net": 1101.0, "cut": 3.1, "fill": 1104.1},
        "volume_thresholded_m3": {"net": 1041.0, "cut": 10.0, "fill": 1051.0},
        "uncertainty_m3": {"net": 6.3, "cut": 1.2, "fill": 6.1},
        "uncertainty": {"lod_m": 0.05, "sigma_m": 0.025, "range_m": 11.0},
        "registration": {"transform": np.eye(4).tolist(),
                         "coarse": {"method": "fpfh", "fitness": 0.8, "rmse": 0.3,
                                    "accepted": False},
                         "fine": {"method": "icp", "fitness": 0.97, "rmse": 0.031}},
        "grid": {"cell_m": 0.5, "rows": 160, "cols": 200, "crs": "WGS 84 / UTM zone 54N",
                 "compared_area_m2": 8000.0},
        "inputs": {"before": {"path": "before <1>.las", "points": 2500000, "crs": "EPSG:32654"},
                   "after": {"path": "after.laz", "points": 1500000}},
        "timings_s": {"read": 0.4, "register": 2.1},
        "correction": {"method": "surface",
                       "params": {"terms": ["1", "x"], "coefficients": [0.05, 0.001],
                                  "residuals": {"mean": 0.0, "std": 0.02, "nmad": 0.019}}},
    }


def arrays() -> dict:
    y, x = np.mgrid[0:GRID.rows, 0:GRID.cols] * GRID.cell
    d = 3 * np.exp(-((x - 50) ** 2 + (y - 40) ** 2) / 100) - np.exp(-((x - 20) ** 2) / 20)
    d[:10, :30] = np.nan
    rng = np.random.default_rng(0)
    filled = np.zeros(d.shape, bool)
    filled[50:55, 60:70] = True
    return {"difference": d, "dem_after": 100 + d + 0.01 * x, "filled_mask": filled,
            "residual": np.where(np.abs(d) < 0.05, rng.normal(0, 0.02, d.shape), np.nan)}


def png_size(uri: str) -> tuple[int, int]:
    data = base64.b64decode(uri.split(",", 1)[1])
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_html_is_self_contained_and_tolerant(tmp_path):
    path = write_html(report(), arrays(), GRID, tmp_path / "report.html")
    text = path.read_text()
    assert "http://" not in text and "https://" not in text
    imgs = dict(re.findall(r'<img id="([\w-]+)" alt="[^"]*" src="(data:image/png;base64,[^"]+)"',
                           text))
    assert set(imgs) == {"difference-map", "histogram", "residual-map"}
    for uri in imgs.values():
        w, h = png_size(uri)
        assert w > 300 and h > 200
    assert "1,040.20 ± 6.30" in text and "before &lt;1&gt;.las" in text
    minimal = write_html({}, {}, GRID, tmp_path / "empty.html").read_text()
    assert "Volumes" in minimal and "<img" not in minimal


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed")
def test_renders_in_headless_chromium(tmp_path):
    path = write_html(report(), arrays(), GRID, tmp_path / "report.html")
    probe = tmp_path / "probe.html"  # the report plus a script that records rendered sizes
    probe.write_text(path.read_text().replace("</body>", (
        "<script>window.addEventListener('load',()=>{document.body.setAttribute('data-imgs',"
        "Array.from(document.images).map(i=>i.id+':'+i.naturalWidth+'x'+i.height).join(';'))})"
        "</script></body>")))
    flags = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
             "--virtual-time-budget=3000"]
    dom = subprocess.run(flags + ["--dump-dom", probe.as_uri()], capture_output=True,
                         text=True, timeout=60).stdout
    sizes = dict(re.findall(r"([\w-]+):(\d+)x\d+", re.search(r'data-imgs="([^"]*)"', dom)[1]))
    for ident in ("difference-map", "histogram", "residual-map"):
        assert int(sizes[ident]) > 300  # decoded, non-broken image
    shot = tmp_path / "shot.png"
    subprocess.run(flags + [f"--screenshot={shot}", "--window-size=1200,2000", path.as_uri()],
                   capture_output=True, timeout=60)
    assert shot.exists()
    assert struct.unpack(">II", shot.read_bytes()[16:24]) == (1200, 2000)
