"""What C libraries print straight to stderr, dropped while a command runs (a full disk adds dozens of
libtiff lines to the one error); ``SOILVOLUME_DEBUG=1`` shows them. ``sys.stderr`` still writes to the
terminal."""

from __future__ import annotations

import faulthandler
import io
import logging
import os
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def hold_native_stderr() -> Iterator[None]:
    """Point file descriptor 2 at the null device and ``sys.stderr`` at the terminal."""
    try:
        real = sys.stderr.fileno() == 2 and not os.environ.get("SOILVOLUME_DEBUG")
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        real = False
    if not real:
        yield
        return
    sys.stderr.flush()
    was_enabled, terminal, python_stderr = faulthandler.is_enabled(), os.dup(2), sys.stderr
    sys.stderr = os.fdopen(
        os.dup(terminal), "w", buffering=1, encoding=python_stderr.encoding, errors="backslashreplace"
    )
    faulthandler.enable(sys.stderr)  # a crash still reports on the terminal
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
    try:
        yield
    finally:
        sys.stderr.flush()
        os.dup2(terminal, 2)
        os.close(terminal)
        sys.stderr.close()
        sys.stderr = python_stderr
        faulthandler.enable(sys.stderr) if was_enabled else faulthandler.disable()


def quiet_library_warnings() -> None:
    """No library's warning reaches the terminal unless asked (``python -W``, ``PYTHONWARNINGS``, which
    the Dask workers inherit): each failure is its one line."""
    if sys.warnoptions:
        return
    warnings.simplefilter("ignore")
    os.environ["PYTHONWARNINGS"] = "ignore"


#: libraries whose log records never reach the terminal: rasterio (GDAL's errors reach us as exceptions), asyncio
#: (Dask's event loop: a task's failure reaches us through its future; a shutdown that outran its timeout on a busy
#: host printed "Future exception was never retrieved" after the run's one-line error)
QUIET_LOGGERS = ("rasterio", "asyncio")


def quiet_library_logs() -> None:
    """:data:`QUIET_LOGGERS`' records handled by a null handler (Python's last resort would print them), unless
    ``SOILVOLUME_DEBUG`` is set."""
    if os.environ.get("SOILVOLUME_DEBUG"):
        return
    for name in QUIET_LOGGERS:
        log = logging.getLogger(name)
        if not any(isinstance(h, logging.NullHandler) for h in log.handlers):
            log.addHandler(logging.NullHandler())
