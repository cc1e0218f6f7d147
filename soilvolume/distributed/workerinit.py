"""Run by every Dask worker process this engine starts (a ``preload``): a terminal's Ctrl-C goes
to the whole process group, and only the driver acts on it (it stops the run and shuts the
cluster down); a worker killed by it would fail its tasks (``FutureCancelledError``). The tile
tasks' modules are imported as the worker starts."""

from __future__ import annotations

import signal


def ignore_interrupts() -> None:
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: the signal goes to the main thread's handler
        pass


def dask_setup(worker=None) -> None:  # noqa: ARG001 - the preload protocol
    ignore_interrupts()
    warm()


def warm() -> None:
    """Import what the tile tasks run (laspy, pyproj, the engine's readers and gridding) while
    the worker starts: the driver reads the first tiles meanwhile, and the first tasks then
    start at once instead of importing for ~0.4 s each (a worker forked from the forkserver has
    them already: :data:`.cluster.FORKSERVER_PRELOAD`)."""
    import importlib

    from ..core.leanimport import without
    from .cluster import TASK_MODULES

    with without():  # laspy's requests (core.leanimport.EXTRAS): a task never reads over HTTP
        for name in TASK_MODULES:
            importlib.import_module(name)


ignore_interrupts()
