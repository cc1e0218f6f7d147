"""Imports a run will need, done in a background thread beside the steps that do not need them.

Open3D (the registrations that use it: GICP, PFH, FPFH) takes ~0.4-0.6 s to import, most of it
loading its native library, and a run needs it only after the inputs are read: imported in a thread
from the start, it overlaps with the reading; the step that needs it waits on Python's module lock
until it is complete. The other modules wait until the reading is done (:func:`reading_done`), until
the run waits on other processes (:func:`idle`: a tiled run's driver waiting for its first pass's
tasks), or while its thread works without the GIL (:func:`off_the_gil`: the native kernel reading
whole chunks of a LAS file, no Python between its pieces), each epoch's stage (:data:`STAGES`)
beside its reading (:func:`reading_epoch`): SciPy's spatial beside the after cloud, for the
footprint; beside the before cloud the registration's and the volume step's (ndimage, sparse
solvers), then rasterio (GeoTIFF output).

Why so: an import holds the GIL (unmarshalling, loading extensions), and Python beside it waits.
- All stages at once ran on beside the Python between the two epochs (the footprint, the crop's
  mask) and held it up 40-60 ms (paper pair: the crop 0.27 -> 0.21 s, 16 interleaved rounds); as
  50 m tiles, each file a window of its own, the footprint took 136 ms instead of 24.
- Beside the numpy reading (two threads, many GIL handoffs) an import slowed the reading by more
  than it saved (reading done ~50 ms later, the run ~40-90 ms longer, 25 interleaved runs).
- Beside the native kernel the imports go ahead and the registration later runs without them
  (the run 1.136 -> 1.076 s, 14 interleaved rounds).
- Importing the later steps' modules (scipy.optimize, the report's) beside the registration's ICP
  was tried: no measurable gain on two cores, and ~30 MB more peak memory.
Nothing is imported that the run would not import anyway.
"""

from __future__ import annotations

import os
import threading

#: what the footprint and the ICP import (SciPy's spatial), then what the registration, the volume
#: step (ndimage, the refill's sparse solvers) and the GeoTIFF output import: each stage goes ahead
#: while the kernel reads its epoch's files without the GIL (:func:`reading_epoch`,
#: :func:`off_the_gil`; the footprint, between the epochs, waits for the first), all once the inputs
#: are read or the run waits
STAGES = (("scipy.spatial",), ("soilvolume.registration.register", "soilvolume.volumes.compute", "rasterio"))
AFTER_READING = tuple(name for stage in STAGES for name in stage)
_GO = tuple(threading.Event() for _ in STAGES)  # each stage's go-ahead
_EPOCH = [0]  # the epoch being read: 0 the first (the after cloud), 1 the next


def reading_done() -> None:
    """The inputs are in memory: imports held back for the memory peak may go ahead, and the
    garbage collector paused for the imports restarts (:mod:`.collector`)."""
    from .collector import resume

    idle()
    resume()


def idle() -> None:
    """The run waits on other processes (a tiled run's driver on its first pass's tasks, its
    points in the workers), or has read its inputs: every held-back import may go ahead."""
    for go in _GO:
        go.set()


def reading_epoch(k: int) -> None:
    """The run starts reading its ``k``-th epoch (0: the after cloud, whose footprint crops the
    next): beside its kernel's reading, the stages up to the ``k``-th may go ahead."""
    _EPOCH[0] = k


def off_the_gil() -> None:
    """The run's thread starts a while in native code without the GIL (the streaming's whole-chunk
    kernel on a file, :mod:`soilvolume.native`): the stages of the held-back imports up to the
    epoch being read go ahead beside it. Not more: an import holds the GIL, and beside the Python
    between the epochs (the footprint, the crop's mask) it slowed that by more than the import
    took (paper pair: the footprint's hull 7 ms of CPU in 40 ms, waiting for the GIL; as 50 m
    tiles, each a window of its own, the footprint 24 -> 136 ms)."""
    for go in _GO[: _EPOCH[0] + 1]:
        go.set()


def _import(open3d: bool) -> None:
    import importlib

    try:
        if open3d:
            from ..registration.o3d import _o3d

            _o3d()
        for go, stage in zip(_GO, STAGES, strict=True):
            go.wait(120.0)
            for name in stage:
                importlib.import_module(name)
    except Exception:  # noqa: BLE001 - the step that needs a package reports it missing itself
        pass


def preload(open3d: bool, threads: int = 0) -> threading.Thread:
    """Start importing Open3D (when the registration uses it: ``open3d``), then, stage by stage
    beside the kernel's reading (:func:`off_the_gil`) or once the inputs are read or the run
    waits (:func:`idle`), :data:`AFTER_READING`, in the background.
    ``threads`` > 0 sets OMP_NUM_THREADS first (as the run does), for OpenMP libraries (Open3D
    0.19+ is limited by :func:`soilvolume.registration.o3d.limit_threads`)."""
    if threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(threads))
    for go in _GO:
        go.clear()
    _EPOCH[0] = 0
    worker = threading.Thread(target=_import, args=(open3d,), name="soilvolume-preload", daemon=True)
    worker.start()
    return worker
