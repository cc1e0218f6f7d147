"""A deliberately naive stand-in for ``soilvolume estimate`` to exercise the harness.

    python bench/standin_cli.py estimate BEFORE AFTER --out DIR [--overwrite]

No registration and no corrections: class-2 mean-height grids of both clouds on the after
footprint, summed difference. It writes DIR/report.json with the same keys the harness reads
(``timings_s`` per stage, ``volume_m3`` net/cut/fill, ``grid``). Its volume is NOT meant to be
right; use it only with ``run_bench.py --cmd`` to test the harness itself.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

T0 = time.perf_counter()

import laspy  # noqa: E402
import numpy as np  # noqa: E402
import rasterio  # noqa: E402
from rasterio.transform import from_origin  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("command", choices=["estimate"])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--out", required=True)
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args()
    timings = {"read": 0.0}
    t = time.perf_counter()
    clouds = []
    for p in (a.before, a.after):
        las = laspy.read(p)
        m = np.asarray(las.classification) == 2
        clouds.append((np.asarray(las.x)[m], np.asarray(las.y)[m], np.asarray(las.z)[m], las.header.parse_crs()))
    timings["read"] = time.perf_counter() - t + (t - T0)

    t = time.perf_counter()
    cell = 0.5
    xa, ya = clouds[1][0], clouds[1][1]
    x0, y0 = np.floor(xa.min() / cell) * cell, np.floor(ya.min() / cell) * cell
    cols = int(np.ceil((xa.max() - x0) / cell))
    rows = int(np.ceil((ya.max() - y0) / cell))
    y1 = y0 + rows * cell
    dems = []
    for x, y, z, _ in clouds:
        c = np.floor((x - x0) / cell).astype(np.int64)
        r = np.floor((y1 - y) / cell).astype(np.int64)
        ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        idx = r[ok] * cols + c[ok]
        s = np.bincount(idx, z[ok], rows * cols)
        n = np.bincount(idx, None, rows * cols)
        with np.errstate(invalid="ignore", divide="ignore"):
            dems.append((s / n).reshape(rows, cols))
    timings["grids"] = time.perf_counter() - t

    t = time.perf_counter()
    diff = dems[1] - dems[0]
    d = diff[np.isfinite(diff)] * cell * cell
    vol = {"net": float(d.sum()), "cut": float(-d[d < 0].sum()), "fill": float(d[d > 0].sum())}
    timings["volume"] = time.perf_counter() - t

    t = time.perf_counter()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    crs = clouds[0][3]
    profile = dict(
        driver="GTiff",
        width=cols,
        height=rows,
        count=1,
        dtype="float32",
        crs=crs.to_wkt() if crs is not None else None,
        nodata=np.nan,
        transform=from_origin(x0, y1, cell, cell),
        compress="deflate",
        tiled=True,
    )
    for name, arr in (("dem_before", dems[0]), ("dem_after", dems[1]), ("difference", diff)):
        with rasterio.open(out / f"{name}.tif", "w", **profile) as dst:
            dst.write(arr.astype(np.float32), 1)
    report = {
        "volume_m3": vol,
        "grid": {"cell_m": cell, "rows": rows, "cols": cols},
        "timings_s": timings,
        "standin": True,
    }
    timings["write"] = time.perf_counter() - t
    (out / "report.json").write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
