"""Run by every Dask worker process this engine starts (a ``preload``; the local cluster's
forkserver imports it first, for the workers it forks): a terminal's Ctrl-C goes to the whole
process group, and only the driver acts on it (it stops the run and shuts the cluster down); a
worker killed by it would fail its tasks (``FutureCancelledError``). The optional extras no task
uses are hidden from the imports that follow (:func:`soilvolume.process.hide_extras`)."""

from __future__ import annotations

import signal

from ..process import WORKER_EXTRAS, hide_extras


def ignore_interrupts() -> None:
    """SIGINT ignored in this process (from its main thread; elsewhere the main thread's handler has it)."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: the signal goes to the main thread's handler
        pass


def dask_setup(worker=None) -> None:  # noqa: ARG001 - the preload protocol
    ignore_interrupts()


ignore_interrupts()
hide_extras(WORKER_EXTRAS)
