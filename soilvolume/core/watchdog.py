"""Every run ends, whatever C loop its threads are in: a thread beside it hears SIGINT/SIGTERM through the
wakeup fd (written even while the main thread waits on native code) and ends a run not stopping within
:data:`GRACE` s (or not ended :data:`STOPPING_S` s after); under ``ulimit -v`` it sees a thread spinning at
the limit (OpenBLAS's endless retry: a series at 600 MB spun 12 minutes) and fails the run after :data:`SPIN_S` s.
A process under an address-space limit fails in one line naming it (:func:`out_of_memory`)."""

from __future__ import annotations

import os
import resource
import select
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator

from . import wording

GRACE = 0.75  # s: a run that has not begun to stop this long after a signal is ended
STOPPING_S = 10.0  # s: a run stopping (its cleanups, a cluster's shutdown) is ended after this
TICK = 0.25  # s: how often the thread looks
STACK = 256 << 10  # bytes: the watching thread's stack
M_ARENA_MAX = -8  # glibc's mallopt parameter
SPIN_S = 3.0  # s: a thread spinning at the address-space limit this long ends the run
SPIN_SYSTEM = 0.3  # the share of a second in system time a spinning thread spends (failed mmaps)
#: the address space OpenBLAS's buffer takes (its 128 MiB and glibc's arena around it), with margin
BLAS_BUFFER = 192 << 20


def address_limit() -> int | None:
    """The process's address-space limit in bytes (RLIMIT_AS's soft limit), None when unlimited."""
    try:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY else int(soft)


def out_of_memory(keyed: bool = False) -> str:
    """The out-of-memory line, naming the limit (``keyed``: its option as a marker, else as a flag)."""
    limit = address_limit()
    under = f" under the address-space limit of {limit / 1e6:,.0f} MB (ulimit -v)" if limit else ""
    said = f"out of memory{under}: use a larger {wording.opt('cell')} or crop the clouds first"
    return said if keyed else wording.cli(said)


def short_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` is a MemoryError or a library that could not be mapped under a limit."""
    if isinstance(exc, MemoryError):
        return True
    text = str(exc).lower()
    return isinstance(exc, ImportError) and ("failed to map segment" in text or "cannot allocate memory" in text)


def start(leave: Callable[[int | None], None], stopping: Callable[[], bool]) -> Callable[[], None]:
    """Start the watching thread of one run (from the main thread); returns what stops it.
    ``leave(signum_or_none)`` is called, from the thread, to end the process."""
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    try:
        old_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    except ValueError:  # not the main thread
        _close(read_fd, write_fd)
        return lambda: None
    done, limit = threading.Event(), address_limit()
    if limit is not None:  # glibc's malloc on two arenas (under ulimit -v, each thread's own 64 MiB arena counts)
        import ctypes
        import ctypes.util

        try:
            ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt(M_ARENA_MAX, 2)
        except (OSError, AttributeError):
            pass
    old = threading.stack_size(STACK)  # a small thread: under ulimit -v its space counts
    try:
        watch = (read_fd, write_fd, done, leave, stopping, limit)
        threading.Thread(target=_watch, args=watch, name="soilvolume-watchdog", daemon=True).start()
    finally:
        threading.stack_size(old)

    def stop() -> None:
        done.set()
        signal.set_wakeup_fd(old_fd)

    return stop


def _watch(read_fd: int, write_fd: int, done: threading.Event, leave, stopping, limit: int | None) -> None:
    deadline, spin = None, _spinning(limit)
    while not done.is_set():
        ready, _, _ = select.select([read_fd], [], [], TICK)
        if ready:
            got = os.read(read_fd, 64)
            if got and deadline is None:
                deadline, signum = time.monotonic() + GRACE, got[0]
        if done.is_set():
            break
        if deadline is not None and time.monotonic() > deadline:
            if not stopping() or time.monotonic() > deadline - GRACE + STOPPING_S:
                leave(signum)
        if next(spin):
            leave(None)
    _close(read_fd, write_fd)


def _close(*fds: int) -> None:
    for fd in fds:
        os.close(fd)


def _spinning(limit: int | None) -> Iterator[bool]:
    """At each tick, whether a thread spun at the address-space ``limit`` (bytes; None: none) for :data:`SPIN_S`
    s: the space unchanged within :data:`BLAS_BUFFER` of it, a thread's system time growing by
    :data:`SPIN_SYSTEM`."""
    since, last = None, None
    while True:
        now, sample = time.monotonic(), None if limit is None else _sample()
        if sample is not None:
            (size, system), prev, last = sample, last, sample
            hot = prev is not None and size == prev[0] and size + BLAS_BUFFER > limit
            per_tick = SPIN_SYSTEM * TICK * os.sysconf("SC_CLK_TCK")
            hot = hot and any(t - prev[1].get(k, t) >= per_tick for k, t in system.items())
            since = (since or now) if hot else None
        yield sample is not None and since is not None and now - since >= SPIN_S


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
