"""Every run ends, whatever C loop its threads are in: a thread beside it hears SIGINT/SIGTERM through the
wakeup fd (written even while the main thread waits on native code) and ends a run not stopping within
:data:`GRACE` s (or not ended :data:`STOPPING_S` s after); under ``ulimit -v`` it sees a thread spinning at
the limit (OpenBLAS's endless retry: a series at 600 MB spun 12 minutes) and fails the run after :data:`SPIN_S` s."""

from __future__ import annotations

import os
import select
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable

from .memlimit import BLAS_BUFFER, address_limit

GRACE = 0.75  # s: a run that has not begun to stop this long after a signal is ended
STOPPING_S = 10.0  # s: a run stopping (its cleanups, a cluster's shutdown) is ended after this
TICK = 0.25  # s: how often the thread looks
STACK = 256 << 10  # bytes: the watching thread's stack
M_ARENA_MAX = -8  # glibc's mallopt parameter
SPIN_S = 3.0  # s: a thread spinning at the address-space limit this long ends the run
SPIN_SYSTEM = 0.3  # the share of a second in system time a spinning thread spends (failed mmaps)


class Watchdog:
    """The watching thread of one run (:meth:`start` in the main thread, :meth:`stop` after it);
    ``leave(signum_or_none)`` is called, from the thread, to end the process."""

    def __init__(self, leave: Callable[[int | None], None], stopping: Callable[[], bool]) -> None:
        self.leave, self.stopping = leave, stopping
        self.done = threading.Event()
        self.old_fd = -1
        self.read_fd = self.write_fd = -1

    def start(self) -> None:
        self.read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.write_fd, False)
        try:
            self.old_fd = signal.set_wakeup_fd(self.write_fd, warn_on_full_buffer=False)
        except ValueError:  # not the main thread
            self._close()
            return
        if address_limit() is not None:
            few_arenas()
        old = threading.stack_size(STACK)  # a small thread: under ulimit -v its space counts
        try:
            threading.Thread(target=self._watch, name="soilvolume-watchdog", daemon=True).start()
        finally:
            threading.stack_size(old)

    def stop(self) -> None:
        if self.read_fd < 0:
            return
        self.done.set()
        signal.set_wakeup_fd(self.old_fd)

    def _close(self) -> None:
        for fd in (self.read_fd, self.write_fd):
            os.close(fd)
        self.read_fd = self.write_fd = -1

    def _watch(self) -> None:
        deadline, spin = None, Spin(address_limit())
        while not self.done.is_set():
            ready, _, _ = select.select([self.read_fd], [], [], TICK)
            if ready:
                got = os.read(self.read_fd, 64)
                if got and deadline is None:
                    deadline, signum = time.monotonic() + GRACE, got[0]
            if self.done.is_set():
                break
            if deadline is not None and time.monotonic() > deadline:
                if not self.stopping() or time.monotonic() > deadline - GRACE + STOPPING_S:
                    self.leave(signum)
            if spin.spinning():
                self.leave(None)
        self._close()


class Spin:
    """Whether a thread spun at the address-space ``limit`` (bytes; None: none) for :data:`SPIN_S` s: the space
    unchanged within :data:`.memlimit.BLAS_BUFFER` of it, a thread's system time growing by :data:`SPIN_SYSTEM`."""

    def __init__(self, limit: int | None) -> None:
        self.limit = limit
        self.since: float | None = None
        self.last: tuple[int, dict[str, int]] | None = None

    def spinning(self) -> bool:
        if self.limit is None:
            return False
        now, sample = time.monotonic(), _sample()
        if sample is None:
            return False
        size, system = sample
        prev, self.last = self.last, sample
        hot = prev is not None and size == prev[0] and size + BLAS_BUFFER > self.limit
        per_tick = SPIN_SYSTEM * TICK * os.sysconf("SC_CLK_TCK")
        hot = hot and any(t - prev[1].get(k, t) >= per_tick for k, t in system.items())
        self.since = (self.since or now) if hot else None
        return self.since is not None and now - self.since >= SPIN_S


def few_arenas() -> None:
    """glibc's malloc on two arenas (under ``ulimit -v``, each thread's own 64 MiB arena counts); else nothing."""
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt(M_ARENA_MAX, 2)
    except (OSError, AttributeError):
        pass


def _sample() -> tuple[int, dict[str, int]] | None:
    """(the address space in bytes, each thread's system time in clock ticks); None off Linux."""
    try:
        with open("/proc/self/statm") as f:
            size = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        system = {}
        for tid in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{tid}/stat") as f:
                system[tid] = int(f.read().rsplit(")", 1)[1].split()[12])
    except (OSError, ValueError, IndexError):
        return None
    return size, system


def remove_process_temp_dir() -> None:
    """The folder multiprocessing made in TMPDIR (the Dask forkserver's socket), which ``os._exit`` leaves."""
    process = sys.modules.get("multiprocessing.process")
    tempdir = process.current_process()._config.get("tempdir") if process else None
    if tempdir:
        shutil.rmtree(tempdir, ignore_errors=True)
