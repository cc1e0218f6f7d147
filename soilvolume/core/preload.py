"""Imports a run will need, done in a background thread while the clouds are read.

Open3D (the registrations that use it: GICP, PFH, FPFH) and rasterio (GeoTIFF output) take
~0.3-0.8 s to import, most of it loading their native libraries, and a run needs them only after
the inputs are read. Imported in a thread from the start, they overlap with the reading (numpy and
laspy release the GIL); the step that needs one waits on Python's module lock until it is
complete. rasterio waits until the reading is done (:func:`reading_done`): the peak memory of a
run is at the end of the reading, and it would add its ~20 MB there. Between the two, while the
clouds are still read, come the modules of the registration and the volume step (:data:`DURING`:
SciPy's ndimage and sparse solvers), which the reading does not need. Nothing is imported that the
run would not import anyway. (Importing the later steps' modules, scipy.optimize and the report's,
beside the registration's ICP was tried: no measurable gain on two cores, and ~30 MB more peak
memory, the thread's allocations then.)
"""

from __future__ import annotations

import os
import threading

_READ = threading.Event()  # set when the inputs are read (the memory peak is behind)
#: what the registration and the volume step import (ndimage, the refill's sparse solvers),
#: imported during the reading, after Open3D
DURING = ("soilvolume.registration.register", "soilvolume.volumes.compute")


def reading_done() -> None:
    """The inputs are in memory: imports held back for the memory peak may go ahead, and the
    garbage collector paused for the imports restarts (:mod:`.collector`)."""
    from .collector import resume

    _READ.set()
    resume()


def _import(open3d: bool) -> None:
    import importlib

    try:
        if open3d:
            from ..registration.o3d import _o3d

            _o3d()
        for name in DURING:
            importlib.import_module(name)
        _READ.wait(120.0)
        importlib.import_module("rasterio")
    except Exception:  # noqa: BLE001 - the step that needs a package reports it missing itself
        pass


def preload(open3d: bool, threads: int = 0) -> threading.Thread:
    """Start importing Open3D (when the registration uses it: ``open3d``), :data:`DURING`, then
    rasterio, in the background. ``threads`` > 0 sets OMP_NUM_THREADS first (as the run does), for
    OpenMP libraries (Open3D 0.19+ is limited by :func:`soilvolume.registration.o3d.limit_threads`)."""
    if threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(threads))
    _READ.clear()
    worker = threading.Thread(target=_import, args=(open3d,), name="soilvolume-preload", daemon=True)
    worker.start()
    return worker
