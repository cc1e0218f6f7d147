"""The I/O floor of one estimate: read both input clouds and write three GeoTIFFs of the grid.

Run as its own process by ``run_bench.py`` (start-up and imports included, like the CLI):

    python bench/floor.py BEFORE AFTER OUTDIR [--cell C] [--bounds XMIN YMIN XMAX YMAX]

Reads both files completely with laspy's chunked reader (scaled float64 x/y/z, classification),
then writes ``dem_before.tif``, ``dem_after.tif`` and ``difference.tif`` (float32, DEFLATE) on a
grid covering the after cloud (or ``--bounds``) at ``--cell`` metres (default: the engine's rule,
>= 8 before points per cell and >= 0.5 m). Prints one JSON line with the timings.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

T0 = time.perf_counter()

import laspy  # noqa: E402
import numpy as np  # noqa: E402
import rasterio  # noqa: E402
from rasterio.transform import from_origin  # noqa: E402


def read_all(path: str) -> tuple[int, np.ndarray, object]:
    """Stream the whole file, materialising scaled float64 x/y/z and the classification of
    every point; return the count, the header bbox (xmin ymin zmin xmax ymax zmax) and CRS."""
    n = 0
    with laspy.open(path) as reader:
        h = reader.header
        crs = h.parse_crs()
        bbox = np.concatenate([h.mins, h.maxs])
        for chunk in reader.chunk_iterator(2_000_000):
            x, y, z = np.asarray(chunk.x), np.asarray(chunk.y), np.asarray(chunk.z)
            c = np.asarray(chunk.classification)
            n += len(x)
            del x, y, z, c
    return n, bbox, crs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("out")
    ap.add_argument("--cell", type=float, default=None)
    ap.add_argument("--bounds", type=float, nargs=4, default=None)
    a = ap.parse_args()
    t_import = time.perf_counter() - T0
    t = time.perf_counter()
    nb, bb, crs = read_all(a.before)
    na, ba, _ = read_all(a.after)
    t_read = time.perf_counter() - t

    t = time.perf_counter()
    cell = a.cell
    if cell is None:
        area = max((bb[3] - bb[0]) * (bb[4] - bb[1]), 1e-9)
        cell = max(0.5, math.sqrt(8.0 / (nb / area)))
    x0, y0, x1, y1 = a.bounds if a.bounds else (ba[0], ba[1], ba[3], ba[4])
    x0, y0 = math.floor(x0 / cell) * cell, math.floor(y0 / cell) * cell
    x1, y1 = math.ceil(x1 / cell) * cell, math.ceil(y1 / cell) * cell
    cols, rows = int(round((x1 - x0) / cell)), int(round((y1 - y0) / cell))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
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
    data = np.full((rows, cols), np.nan, dtype=np.float32)
    for name in ("dem_before", "dem_after", "difference"):
        with rasterio.open(out / f"{name}.tif", "w", **profile) as dst:
            dst.write(data, 1)
    t_write = time.perf_counter() - t
    print(
        json.dumps(
            {
                "points": nb + na,
                "cell_m": cell,
                "rows": rows,
                "cols": cols,
                "import_s": t_import,
                "read_s": t_read,
                "write_s": t_write,
            }
        )
    )


if __name__ == "__main__":
    main()
