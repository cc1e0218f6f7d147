"""``soilvolume selftest``: is this installation complete and working? Every dependency imports
(with the features the engine needs), a seeded pair of a few thousand points is written as LAZ
and estimated, and the net volume lands near the pair's known truth."""

from __future__ import annotations

import importlib
import json
import os
import tempfile
import time
from pathlib import Path

from .. import api
from ..core.hooks import Hooks
from ..core.outputs import os_errors, output_dir
from ..core.types import SoilVolumeError
from ..distributed import cluster
from ..options import Options
from ..registration.o3d import _o3d  # Open3D as the engine imports it (without its web drawing)
from .synthetic import SceneConfig, write_pair_streaming

#: module -> attribute that must exist (an old version lacks it)
MODULES = {
    "numpy": "ndarray",
    "scipy.ndimage": "label",
    "pyproj": "CRS",
    "rasterio": "open",
    "laspy": "LazBackend",
    "lazrs": "LasZipDecompressor",
    "open3d": "geometry",
    "dask": "delayed",
    "distributed": "LocalCluster",
    "shapely": "make_valid",
    "pyogrio": "read_info",
    "CSF": "CSF",  # --ground csf
}
POINTS = (12_000, 8_000)  # before, after: 0.5 and 1.9 points/m²
NET_TOLERANCE = 0.1  # relative: a smoke test on 3 m cells (measured 0.8 %), not an accuracy test


def check_imports() -> dict[str, str]:
    """{module: version} of every dependency; SoilVolumeError naming the first that fails."""
    versions = {}
    for name, attribute in MODULES.items():
        try:
            module = _o3d() if name == "open3d" else importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 - ImportError, OSError of a missing library, ...
            raise SoilVolumeError(f"cannot import {name} ({type(exc).__name__}: {exc})") from exc
        if not hasattr(module, attribute):
            raise SoilVolumeError(f"{name} {getattr(module, '__version__', '?')} is too old (no {attribute})")
        versions[name] = str(getattr(module, "__version__", ""))
    import pyproj

    if not hasattr(pyproj.CRS, "to_2d"):
        raise SoilVolumeError(f"pyproj {pyproj.__version__} is too old (needs 3.6 or newer)")
    return versions


def check_spawned_worker(scratch: Path) -> float:
    """A Dask LocalCluster of one worker started by ``spawn`` (how Windows and macOS start every
    worker: a fresh interpreter that must find the engine and its packages) runs an engine task."""
    started = time.perf_counter()
    try:
        made, client = cluster.local(1, True, None, scratch, spawn=True)
    except Exception as exc:  # noqa: BLE001 - whatever stops a worker from starting
        raise SoilVolumeError(f"a Dask worker process does not start ({type(exc).__name__}: {exc})") from exc
    try:
        answer = client.submit(_answer, 41, pure=False).result(timeout=120)
    except Exception as exc:  # noqa: BLE001
        raise SoilVolumeError(f"a Dask worker process cannot run the engine ({type(exc).__name__}: {exc})") from exc
    finally:
        cluster.shut(made, client)
    if answer[:2] != (42, "soilvolume.scenes.selftest") or answer[2] == os.getpid():
        raise SoilVolumeError(f"a Dask worker process answered {answer!r}")
    return time.perf_counter() - started


def _answer(n: int) -> tuple[int, str, int]:
    """What a worker answers: the engine module it ran in (imported by the worker itself) and
    its process."""
    return n + 1, __name__, os.getpid()


def run_selftest(out: Path, hooks: Hooks) -> dict:
    """Imports, then a tiny seeded estimate in ``out`` (replaced as a whole)."""
    t0 = time.perf_counter()
    hooks.step(5, "importing the engine's dependencies")
    versions = check_imports()
    hooks.step(10, "starting a Dask worker process (spawned)")
    with tempfile.TemporaryDirectory(prefix="soilvolume-selftest-dask-", ignore_cleanup_errors=True) as scratch:
        worker_s = check_spawned_worker(Path(scratch))
    hooks.step(20, f"writing a seeded pair of {POINTS[0]:,} + {POINTS[1]:,} points")
    with output_dir(Path(out), [], True, ("data", "result")) as staged, os_errors(staged.final):
        data = staged.path("data")
        data.mkdir()
        cfg = SceneConfig.small(before_points=POINTS[0], after_points=POINTS[1])
        before, after, truth_path = write_pair_streaming(0, cfg, data, "laz")
        truth = json.loads(truth_path.read_text())
        hooks.step(30, "estimating its volume change")
        res = api.estimate(before, after, staged.path("result"), Options(cell=3.0), overwrite=True, hooks=Hooks())
        net = res.report["volume_m3"]["net"]
        if not abs(net - truth["net"]) <= NET_TOLERANCE * abs(truth["net"]):  # nothing is kept then
            raise SoilVolumeError(f"self-test: net {net:+.1f} m³ where the seeded pair holds {truth['net']:+.1f} m³")
    hooks.step(100, f"self-test passed: net {net:+.1f} m³ (true {truth['net']:+.1f} m³)")
    return {
        "versions": versions,
        "dask_worker_s": round(worker_s, 2),
        "net_m3": net,
        "true_net_m3": truth["net"],
        "seconds": time.perf_counter() - t0,
    }
