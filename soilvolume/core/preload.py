"""Imports a run will need, done in a background thread beside the steps that do not need them.

Open3D (the registrations that use it: GICP, PFH, FPFH) takes ~0.4-0.6 s to import, most of it
loading its native library, and a run needs it only after the inputs are read: imported in a thread
from the start, it overlaps with the reading; the step that needs it waits on Python's module lock
until it is complete. The other modules wait until the reading is done (:func:`reading_done`), until
the run waits on other processes (:func:`idle`: a tiled run's driver waiting for its first pass's
tasks), or until its thread works without the GIL (:func:`off_the_gil`: the native kernel reading
whole chunks of a LAS file, no Python between its pieces): the registration's and the volume
step's (:data:`AFTER_READING`: SciPy's spatial, ndimage and sparse solvers), then rasterio
(GeoTIFF output). The numpy reading keeps both cores busy with its two threads and many GIL
handoffs; an import beside it, holding the GIL in long C calls (unmarshalling, loading extensions),
slowed it by more than it saved (paper pair, 2 cores: reading done ~50 ms later, the run ~40-90 ms
longer, 25 interleaved runs). Beside the native kernel the imports go ahead and the registration
later runs without them (paper pair: the run 1.136 -> 1.076 s, 14 interleaved rounds; the reading
~30 ms longer, the registration ~65 ms shorter). Nothing is imported that the run would not import
anyway. (Importing the later steps' modules, scipy.optimize and the report's, beside the registration's ICP
was tried: no measurable gain on two cores, and ~30 MB more peak memory, the thread's allocations
then.)
"""

from __future__ import annotations

import os
import threading

_GO = threading.Event()  # set when the inputs are read (the memory peak is behind) or the run waits
#: what the footprint and the ICP import (SciPy's spatial), the registration and the volume step
#: (ndimage, the refill's sparse solvers), then GeoTIFF output, imported once the inputs are read
#: or the kernel reads without the GIL (the footprint waits for the first)
AFTER_READING = ("scipy.spatial", "soilvolume.registration.register", "soilvolume.volumes.compute", "rasterio")


def reading_done() -> None:
    """The inputs are in memory: imports held back for the memory peak may go ahead, and the
    garbage collector paused for the imports restarts (:mod:`.collector`)."""
    from .collector import resume

    _GO.set()
    resume()


def idle() -> None:
    """The run waits on other processes (a tiled run's driver on its first pass's tasks, its
    points in the workers): the held-back imports may go ahead meanwhile."""
    _GO.set()


def off_the_gil() -> None:
    """The run's thread works in native code that releases the GIL for a while (the streaming's
    whole-chunk kernel, :mod:`soilvolume.native`): the held-back imports may go ahead beside it."""
    _GO.set()


def _import(open3d: bool) -> None:
    import importlib

    try:
        if open3d:
            from ..registration.o3d import _o3d

            _o3d()
        _GO.wait(120.0)
        for name in AFTER_READING:
            importlib.import_module(name)
    except Exception:  # noqa: BLE001 - the step that needs a package reports it missing itself
        pass


def preload(open3d: bool, threads: int = 0) -> threading.Thread:
    """Start importing Open3D (when the registration uses it: ``open3d``), then, once the inputs
    are read or the run waits (:func:`idle`), :data:`AFTER_READING`, in the background.
    ``threads`` > 0 sets OMP_NUM_THREADS first (as the run does), for OpenMP libraries (Open3D
    0.19+ is limited by :func:`soilvolume.registration.o3d.limit_threads`)."""
    if threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(threads))
    _GO.clear()
    worker = threading.Thread(target=_import, args=(open3d,), name="soilvolume-preload", daemon=True)
    worker.start()
    return worker
