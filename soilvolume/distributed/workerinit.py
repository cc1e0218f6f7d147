"""Every Dask worker process of this engine's preload (the forkserver imports it first): a
terminal's Ctrl-C reaches the whole process group and only the driver acts on it (a worker it
killed would fail its tasks); the extras no task uses hidden (:func:`soilvolume.process.hide_extras`)."""

from __future__ import annotations

import contextlib
import signal

from ..process import WORKER_EXTRAS, hide_extras


def ignore_interrupts() -> None:
    """SIGINT ignored in this process (from its main thread; elsewhere the main thread's handler has it)."""
    with contextlib.suppress(ValueError):  # not the main thread
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def dask_setup(worker=None) -> None:  # noqa: ARG001 - the preload protocol
    ignore_interrupts()


ignore_interrupts()
hide_extras(WORKER_EXTRAS)
