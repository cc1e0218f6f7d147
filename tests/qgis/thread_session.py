"""Four runs as QgsProcessingAlgRunnerTask in worker threads of one QGIS process (a stock QGIS
Python: nothing of the dev venv on any path), then every other algorithm once; prints a JSON
summary with each run's result and what the QGIS process loaded (modules, shared libraries).

Usage: thread_session.py PLUGINS_DIR OUT_DIR REAL_DIR
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from qgis.core import (
    QgsApplication,
    QgsProcessingAlgRunnerTask,
    QgsProcessingContext,
    QgsProcessingFeedback,
)
from session import start  # tests/qgis/session.py, beside this script

HEAVY = ("numpy", "scipy", "pyproj", "rasterio", "open3d", "laspy", "lazrs", "dask", "distributed", "fiona")
WHEEL_LIBS = (
    "pyproj.libs",
    "rasterio.libs",
    "fiona.libs",
    "numpy.libs",
    "scipy.libs",
    "open3d",
    "lazrs",
    "soilvolume/engine",
)


def loaded_heavy() -> dict[str, str]:
    return {
        n: str(getattr(m, "__file__", ""))
        for n, m in list(sys.modules.items())
        if n.split(".")[0] in HEAVY and "." not in n
    }


def children() -> list[str]:
    """Processes this one started that are still alive (an engine left behind would be one)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            name, rest = stat.read_text().rsplit(")", 1)
        except OSError:
            continue
        state, ppid = rest.split()[:2]
        if int(ppid) == os.getpid() and state != "Z":
            alive.append(name.split("(", 1)[1])
    return alive


def main(plugins_dir: str, out_dir: str, real: str) -> int:
    app, _provider, before_plugin = start(plugins_dir, gui=False)
    registry = QgsApplication.processingRegistry()
    out, r = Path(out_dir), Path(real)
    pairs = {
        "autzen": (r / "autzen_bmx_2010.las", r / "autzen_bmx_2023.las"),
        "tommy": (r / "tommy_thompson_park_2015.laz", r / "tommy_thompson_park_2023.laz"),
    }
    jobs = []
    for i in range(4):
        name = ("autzen", "tommy")[i % 2]
        before, after = pairs[name]
        params = {"BEFORE": str(before), "AFTER": str(after), "DIFFERENCE": str(out / f"t{i}.tif")}
        params["DEM_BEFORE"] = str(out / f"t{i}_before.tif")
        params["DEM_AFTER"] = str(out / f"t{i}_after.tif")
        jobs.append((name, registry.createAlgorithmById("soilvolume:estimatevolumechange"), params))
    done: dict[int, tuple] = {}
    tasks, keep = [], []
    t0 = time.time()
    for i, (_name, alg, params) in enumerate(jobs):
        context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
        task = QgsProcessingAlgRunnerTask(alg, params, context, feedback)
        task.executed.connect(lambda ok, results, i=i: done.__setitem__(i, (ok, results)))
        keep.append((context, feedback, alg))
        tasks.append(task)
        QgsApplication.taskManager().addTask(task)
    while len(done) < len(tasks) and time.time() - t0 < 900:
        QgsApplication.processEvents()
        time.sleep(0.05)
    runs = [
        {
            "pair": jobs[i][0],
            "ok": done.get(i, (False, {}))[0],
            "net": (done.get(i, (False, {}))[1] or {}).get("NET_VOLUME"),
        }
        for i in range(len(jobs))
    ]
    seconds = time.time() - t0
    from qgis import processing

    others = {}
    before, after = pairs["tommy"]
    others["pointcloudtodem"] = processing.run(
        "soilvolume:pointcloudtodem", {"INPUT": str(after), "OUTPUT": str(out / "dem.tif")}
    )["VALID_CELLS"]
    others["registerpointclouds"] = processing.run(
        "soilvolume:registerpointclouds", {"BEFORE": str(before), "AFTER": str(after), "OUTPUT": str(out / "reg.laz")}
    )["RMSE"]
    volume = processing.run(
        "soilvolume:volumefromdems",
        {"BEFORE": str(out / "t1_before.tif"), "AFTER": str(out / "t1_after.tif"), "OUTPUT": str(out / "dod.tif")},
    )
    others["volumefromdems"] = [volume["NET_VOLUME"], volume["MEDIAN_DIFFERENCE"]]
    maps = Path("/proc/self/maps").read_text() if Path("/proc/self/maps").exists() else ""
    libs = sorted({line.split()[-1] for line in maps.splitlines() if any(w in line for w in WHEEL_LIBS)})
    new = {n: f for n, f in loaded_heavy().items() if n not in before_plugin}
    summary = {"runs": runs, "seconds": seconds, "others": others, "new_modules": new, "wheel_libraries": libs}
    summary["children"] = children()
    print("RESULT" + json.dumps(summary), flush=True)
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
