"""``python -m soilvolume`` and the ``soilvolume`` console command: a signal that arrives while
the program is still importing ends it with one line, like one during a run."""

import os
import signal
import sys


def _early(signum: int, _frame) -> None:
    """A signal while the program is still importing: nothing was written yet; leave at once."""
    name = "SIGINT" if signum == signal.SIGINT else "SIGTERM"
    sys.stderr.write(f"soilvolume: error: interrupted by {name}; nothing was written\n")
    os._exit(128 + signum)


def run() -> int:
    """Install the early handlers, pause the garbage collector, set how numpy loads
    (:func:`one_blas_thread`, :func:`small_pages`), have pyproj imported lean when
    the command imports it (:mod:`.core.leanimport`), import the command line (it takes a
    moment), run it; ``main`` installs the run's own handlers."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _early)
    from .core.collector import pause

    pause()  # while the modules load (core.collector)
    one_blas_thread()
    small_pages()
    from .core import leanimport

    leanimport.install()  # pyproj, when the command imports it
    from .cli import main

    return leave(main())


def one_blas_thread() -> None:
    """numpy's OpenBLAS on one thread in the command's process, unless the user's environment says
    otherwise (``OPENBLAS_NUM_THREADS``); read once, when numpy loads, so set before any import.
    The engine's matrix products are points times a 3x3 or small least squares, memory-bound;
    with a thread per core, OpenBLAS's idle threads spin (sched_yield) after every product: 1.3 s
    of system time in a 5 s run on two cores, taken from Open3D's threads and the preload
    thread. Open3D's threads are ``--threads``."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def small_pages() -> None:
    """numpy's large arrays on ordinary 4 KiB pages, not transparent huge pages, unless the user's
    environment says otherwise (``NUMPY_MADVISE_HUGEPAGE``; read once, when numpy loads). A
    virtual machine's guest hands free 2 MiB blocks back to its host (free page reporting), and a
    huge page is such a block: each one faulted in is zeroed again by the host, and a run's
    reading then took 0.2 s more system time in ~2 of 3 runs. Paper pair on this project's 2-core
    KVM runner, 12 rounds back to back: 1.044 -> 0.923 s (0.898-0.938 s, against 0.890-1.137 s),
    twice the page faults at half the system time; 64 M-point pair 5.7 -> 3.5 s. Dask's workers
    inherit it."""
    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")


def leave(code: int) -> int:
    """End the process with ``code`` once the command returned, without the interpreter's teardown
    (0.4-0.6 s of freeing numpy, pyproj, rasterio and Open3D, which report.json's ``timings_s``
    cannot count): by then every output is written and closed, every pool and cluster shut; what
    the teardown would remove from TMPDIR is removed here."""
    import logging

    from .core.interrupt import remove_process_temp_dir

    logging.shutdown()
    remove_process_temp_dir()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said
            pass
    os._exit(code if isinstance(code, int) else 1)


if __name__ == "__main__":
    sys.exit(run())
