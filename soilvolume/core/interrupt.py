"""SIGINT/SIGTERM as a flag the engine checks between steps (:func:`check`, called by ``Hooks.step`` and
every iteration callback), never an exception raised inside native code. A second signal of a run that
does not stop runs the registered cleanups and exits at once."""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from . import watchdog
from .types import SoilVolumeError
from .watchdog import out_of_memory

_pending: list[int] = []
_stopping: list[bool] = []
_cleanups: list[Callable[[], str | None]] = []
NAMES = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}


class Interrupted(SoilVolumeError):
    """The run received SIGINT or SIGTERM; nothing was written (``kept``: where a tiled run keeps
    its finished tiles for the same command to resume)."""

    def __init__(self, signum: int, kept: str | None = None) -> None:
        self.signum, self.exit_code = signum, 128 + signum  # the shell's convention: 130 SIGINT, 143 SIGTERM
        said = f"interrupted by {NAMES.get(signum, signum)}; nothing was written"
        if kept:
            said += f" to the output folder; finished tiles are kept in {kept} for the same command to resume"
        super().__init__(said)


def _record(signum: int, _frame) -> None:
    if _pending:  # second signal: the run is stuck in a long native call; leave now
        leave(signum)
    _pending.append(signum)


def leave(signum: int | None) -> None:
    """End the process now, the cleanups run (last first): interrupted by ``signum``, or (None) out of memory;
    the kept tiles' folder named when a cleanup says it kept them."""
    kept = None
    for fn in reversed(_cleanups):
        try:
            kept = fn() or kept
        except Exception:  # noqa: BLE001 - best effort on the way out
            pass
    watchdog.remove_process_temp_dir()
    said = str(Interrupted(signum, kept)) if signum else out_of_memory()
    try:
        sys.stderr.write(f"soilvolume: error: {said}\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum if signum else 1)


def check() -> None:
    """Raise :class:`Interrupted` when a signal arrived since the handlers were installed."""
    if _pending:
        _stopping.append(True)  # the run saw it: the watchdog lets it stop
        raise Interrupted(_pending[0])


@contextmanager
def handle_signals(then_ignore: bool = False) -> Iterator[None]:
    """Record SIGINT/SIGTERM for :func:`check` while the block runs (main thread only), then restore the
    handlers, or with ``then_ignore`` ignore the signals (a finished program is not killed on its way out)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, _record) for s in NAMES}
    stop = watchdog.start(leave, lambda: bool(_stopping))  # a run stuck in native code ends all the same
    try:
        yield
    finally:
        stop()
        for s, h in old.items():
            signal.signal(s, signal.SIG_IGN if then_ignore else h)
        _pending.clear()
        _stopping.clear()


@contextmanager
def cleanup_on_exit(fn: Callable[[], str | None]) -> Iterator[None]:
    """Run ``fn`` if the process is forced out in the block; a path it returns is where tiles were kept."""
    _cleanups.append(fn)
    try:
        yield
    finally:
        _cleanups.remove(fn)
