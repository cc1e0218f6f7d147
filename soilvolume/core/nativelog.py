"""What C libraries print straight to stderr, dropped while a command runs (a full disk adds dozens of
libtiff lines to the one error); ``SOILVOLUME_DEBUG=1`` shows them. ``sys.stderr`` still writes to the
terminal."""

from __future__ import annotations

import faulthandler
import io
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
