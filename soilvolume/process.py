"""The settings of the ``soilvolume`` command's own process, in one place, made by
:mod:`soilvolume.__main__` only (a program importing the engine keeps its process as it is).

Each is kept because a benchmark shows its gain today (``bench/README.md``, *Process settings*:
the paper-sized pair, and its 50 m LAS tiles on ``--scheduler local:2``, with and without,
interleaved); the others, which gained under 5 % of the wall time and 10 % of the peak memory,
were removed. It imports no numpy (nor anything that does): :func:`settle` runs before numpy is loaded.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
import threading

from .core.watchdog import remove_process_temp_dir

#: optional extras libraries import when installed, for functions the engine never calls:
#: requests (laspy: COPC over HTTP); in the Dask workers also jinja2 (Dask: notebook HTML of its
#: objects), which the command's own process needs for report.html
EXTRAS = ("requests",)
WORKER_EXTRAS = (*EXTRAS, "jinja2")
#: the heavy libraries a run's later steps import where they use them, in the order they are first
#: needed (the registration's neighbours, the volume step's labels and sparse solvers, the GeoTIFFs, the report)
AHEAD = ("scipy.spatial", "scipy.ndimage", "scipy.sparse.linalg", "rasterio.io", "jinja2")
#: the commands that read surveys and run the method (the others need none of :data:`AHEAD` soon)
RUNS = frozenset({"estimate", "series", "register", "volume", "dem", "stockpile"})


def settle() -> None:
    """Set what numpy reads as it loads, in this process and the Dask workers it starts (they
    inherit the environment): :func:`one_blas_thread`; and :func:`hide_extras`."""
    one_blas_thread()
    hide_extras()


def hide_extras(names: tuple[str, ...] = EXTRAS) -> None:
    """The modules ``names`` not imported yet seen as not installed by every later import in
    this process (a library then leaves its optional extra out, as it allows): laspy's and Dask's
    imports take no ``requests`` (and in the workers no ``jinja2``; LAS tiles on local:2 without
    this: +14 % wall, +12 % CPU). Also made by the local cluster's workers with
    :data:`WORKER_EXTRAS` (``distributed/workerinit``), whose forkserver imports laspy and Dask."""
    for name in names:
        sys.modules.setdefault(name, None)  # type: ignore[arg-type]


def one_blas_thread() -> None:
    """numpy's OpenBLAS on one thread, unless the user's environment says otherwise
    (``OPENBLAS_NUM_THREADS``). The engine's matrix products are points times a 3x3 or small
    least squares, memory-bound; with a thread per core OpenBLAS's idle threads spin after every
    product, taking the cores from Open3D's threads and the reading (paper pair: +27 % CPU and
    about +80 % wall time with two threads)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def import_ahead(argv: list[str]) -> threading.Thread | None:
    """For a command that runs the method (:data:`RUNS`, not its ``--help``), import :data:`AHEAD`
    in a background thread: an import holds the GIL, the reading of the inputs (the native kernel)
    does not, so they overlap and the steps find the libraries loaded (paper pair: see
    ``bench/README.md``, *Process settings*). A library that fails to import is left to the step
    that needs it to report."""
    if not argv or argv[0] not in RUNS or {"-h", "--help"} & set(argv):
        return None
    worker = threading.Thread(target=_import_all, name="soilvolume-import-ahead", daemon=True)
    worker.start()
    return worker


def _import_all() -> None:
    for name in AHEAD:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - the step that uses it says what is missing
            return


def leave(code: int) -> int:
    """End the process with ``code`` once the command returned, without the interpreter's
    teardown (freeing numpy, pyproj, rasterio and Open3D's objects one by one: paper pair +34 %
    wall time with it): by then every output is written and closed, every pool and cluster
    shut; what the teardown would remove from TMPDIR is removed here."""
    logging.shutdown()
    remove_process_temp_dir()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said
            pass
    os._exit(code if isinstance(code, int) else 1)
