"""The ``soilvolume`` command's own process settings, made by :mod:`soilvolume.__main__` only, each kept
for its measured gain (``bench/README.md``, *Process settings*; those under 5 % wall and 10 % peak memory
were removed). No numpy here: :func:`one_blas_thread` (read by numpy as it loads, here and in the Dask
workers) and :func:`hide_extras` run before it loads."""

from __future__ import annotations

import importlib
import logging
import os
import sys
import threading

from .core.watchdog import remove_process_temp_dir

#: optional extras libraries import for functions the engine never calls: requests (laspy's COPC over
#: HTTP); in the Dask workers jinja2 too (Dask's notebook HTML; the command needs it for report.html)
EXTRAS = ("requests",)
WORKER_EXTRAS = (*EXTRAS, "jinja2")


def hide_extras(names: tuple[str, ...] = EXTRAS) -> None:
    """The modules ``names`` not yet imported seen as not installed by later imports, so laspy and Dask
    leave their extras out (LAS tiles on local:2 without it: +14 % wall, +12 % CPU); the workers hide
    :data:`WORKER_EXTRAS` (``distributed/workerinit``)."""
    for name in names:
        sys.modules.setdefault(name, None)  # type: ignore[arg-type]


def one_blas_thread() -> None:
    """numpy's OpenBLAS on one thread unless ``OPENBLAS_NUM_THREADS`` says otherwise: its products are
    memory-bound, and idle BLAS threads spin after each, taking the cores from Open3D and the reading
    (paper pair with two threads: +27 % CPU, about +80 % wall time)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


#: the heavy libraries a run's later steps import where they use them, in the order first needed
AHEAD = ("scipy.spatial", "scipy.ndimage", "scipy.sparse.linalg", "rasterio.io", "jinja2")
RUNS = frozenset({"estimate", "series", "register", "dem", "stockpile"})


def import_ahead(argv: list[str], gate: threading.Event) -> None:
    """For a run (:data:`RUNS`), import :data:`AHEAD` in a background thread, each only while ``gate``
    is set (the native kernel reading a file without the GIL, a tiled run's driver waiting for its tasks)."""
    if argv and argv[0] in RUNS and not {"-h", "--help"} & set(argv):
        threading.Thread(target=_import_all, args=(gate,), name="soilvolume-import-ahead", daemon=True).start()


def _import_all(gate: threading.Event) -> None:
    for name in AHEAD:
        gate.wait()
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - the step that uses it says what is missing
            return


def leave(code: int) -> int:
    """End the process with ``code`` once the command returned (outputs closed, pools and clusters shut),
    without the interpreter's teardown (paper pair: +34 % wall time), its TMPDIR folder removed here."""
    logging.shutdown()
    remove_process_temp_dir()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said
            pass
    os._exit(code if isinstance(code, int) else 1)
