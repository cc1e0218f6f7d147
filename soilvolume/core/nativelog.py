"""What C libraries print straight to stderr, held back while a command runs and dropped (a full disk
adds dozens of libtiff lines to the one error); ``SOILVOLUME_DEBUG=1`` shows them. ``sys.stderr`` still
writes to the terminal."""

from __future__ import annotations

import faulthandler
import io
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager


class Held:
    """The native stderr text of a block, available once it ended."""

    text = ""


def _real_stderr() -> bool:
    try:
        return sys.stderr.fileno() == 2 and not os.environ.get("SOILVOLUME_DEBUG")
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        return False


@contextmanager
def hold_native_stderr() -> Iterator[Held]:
    """Point file descriptor 2 at a temporary file and ``sys.stderr`` at the terminal."""
    held = Held()
    if not _real_stderr():
        yield held
        return
    sys.stderr.flush()
    was_enabled = faulthandler.is_enabled()
    terminal = os.dup(2)
    python_stderr = sys.stderr
    sys.stderr = os.fdopen(
        os.dup(terminal), "w", buffering=1, encoding=python_stderr.encoding, errors="backslashreplace"
    )
    faulthandler.enable(sys.stderr)  # a crash still reports on the terminal
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield held
        finally:
            sys.stderr.flush()
            os.dup2(terminal, 2)
            os.close(terminal)
            sys.stderr.close()
            sys.stderr = python_stderr
            faulthandler.enable(sys.stderr) if was_enabled else faulthandler.disable()
            sink.seek(0)
            held.text = sink.read().decode(errors="replace")


def quiet_library_warnings() -> None:
    """No library's warning reaches the terminal unless asked (``python -W``, ``PYTHONWARNINGS``, which
    the Dask workers inherit): each failure is its one line."""
    if sys.warnoptions:
        return
    warnings.simplefilter("ignore")
    os.environ["PYTHONWARNINGS"] = "ignore"
