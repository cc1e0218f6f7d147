"""Every wait on a Dask cluster, with a timeout: starting it or connecting to it (no answer, no
workers, a server that speaks something else) and shutting it down; each failure one line naming
the scheduler. Waiting for its tasks: :mod:`.waiting`."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

from ..core import interrupt
from ..core.hooks import Cancelled
from ..core.types import SoilVolumeError, short_error
from ..core.wording import opt

CONNECT_S = 20.0  # a scheduler's address must answer within this
START_S = {"tcp": 35.0, "local": 180.0, "threads": 120.0}  # the whole start, workers included
NO_WORKERS_S = 20.0  # a cluster without any worker for this long cannot run the tasks
POLL_S = 0.25  # how often a wait checks for signals and the cluster's health
CLOSE_S = 15.0  # shutting the client and the cluster down
WORKER_INIT = "soilvolume.distributed.workerinit"
# Dask's statistical profiler samples every worker thread's stack every 10 ms: half of an idle
# worker's CPU, and more on a busy one; nothing of this engine reads it
QUIET = {"distributed.worker.profile.enabled": False}
# the engine's local workers live for one run and size their tasks to their memory: glibc's own
# malloc thresholds, as in-process. Dask's pre-spawn MALLOC_TRIM_THRESHOLD_ (64 KB) also fixes the
# mmap threshold at 128 KB, so every larger temporary goes back to the kernel when freed and is
# faulted in again (0.14 s of the paper pair's 2.5 s as a VPC on local:2); None: not set
LOCAL_WORKER_ENV = {"MALLOC_TRIM_THRESHOLD_": None}
# what the tile tasks run (the forkserver imports them once, for every worker it forks)
TASK_MODULES = ("soilvolume.distributed.scan", "soilvolume.distributed.tiletask", "laspy", "pyproj")
#: imported once by the forkserver, for every worker forked from it (WORKER_INIT first: the
#: extras it hides are left out of Dask's and laspy's imports)
FORKSERVER_PRELOAD = (WORKER_INIT, "distributed", *TASK_MODULES, f"{__package__}.forkfreeze")


class Starting:
    """A (cluster or None, client) started on a daemon thread, used as its client: waited for
    (:attr:`wait`) at its first use, so the driver's work until then (opening the sources, reading
    their first chunks) overlaps the workers' start. A wait ends at its timeout; a cluster nobody
    waits for any more is shut when it arrives. ``here``: its workers run on this machine."""

    def __init__(self, start: Callable[[], tuple], what: str, timeout: float, here: bool = True) -> None:
        self.what, self.timeout, self.here, self._client = what, timeout, here, None
        self.future: Future = Future()
        self.lock, self.abandoned = threading.Lock(), False
        self.closing: threading.Thread | None = None
        self.wait: Callable[[], object] = self.result  # the first use's wait (a run's: timed, cancellable)
        threading.Thread(target=self._run, args=(start,), daemon=True, name="soilvolume-cluster").start()

    def ready(self) -> bool:
        """Whether the cluster is up (or failed: the next use says why); a remote one always (its
        workers read their tiles, the driver none)."""
        return self._client is not None or self.future.done() or not self.here

    def resolve(self):
        """The client (waiting for it the first time)."""
        if self._client is None:
            self._client = self.wait()
        return self._client

    def __getattr__(self, name: str):  # the client's own
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.resolve(), name)

    def _run(self, start) -> None:
        try:
            made = start()
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            self.future.set_exception(exc)
            return
        with self.lock:
            late = self.abandoned
            if not late:
                self.future.set_result(made)
        if late:
            shut(*made)

    def result(self, check: Callable[[], None] = interrupt.check):
        """The client, once started (``check`` runs every :data:`POLL_S`)."""
        deadline = time.monotonic() + self.timeout
        while True:
            check()
            try:
                return self.future.result(timeout=POLL_S)[1]
            except FutureTimeout:
                if time.monotonic() > deadline:
                    raise SoilVolumeError(
                        f"{opt('scheduler', self.what)}: no answer within {self.timeout:.0f} s "
                        "(is it a Dask scheduler?)"
                    ) from None
            except SoilVolumeError:
                raise
            except Exception as exc:  # noqa: BLE001 - a worker killed by the same Ctrl-C, a port taken, ...
                check()
                why = f"{type(exc).__name__}: {short_error(exc)}"
                raise SoilVolumeError(
                    f"{opt('scheduler', self.what)}: the Dask cluster did not start ({why})"
                ) from None

    def close(self) -> None:
        """Shut the cluster down, or wait (bounded) for :meth:`close_soon`'s shutdown. A cluster
        still starting (the run ended by an error or a signal) is waited for, at most
        :data:`CLOSE_S`, and shut here: its workers would otherwise come up after this process,
        into the run's scratch space removed already; later, its starting thread shuts it."""
        if self.closing is not None:
            self.closing.join(2 * CLOSE_S + 1)
            return
        with contextlib.suppress(FutureTimeout):
            self.future.exception(timeout=CLOSE_S)
        self._shut()

    def _shut(self) -> None:
        with self.lock:
            self.abandoned = True
            done = self.future.done() and self.future.exception() is None
        if done:
            shut(*self.future.result())

    def close_soon(self) -> None:
        """Shut the cluster down on a thread (~1 s, overlapping the driver's last steps) once the
        run needs it no more; :meth:`close` waits for it."""
        if self.closing is None:
            self.closing = threading.Thread(target=self._shut, daemon=True, name="soilvolume-cluster-close")
            self.closing.start()


def shut(cluster, client) -> None:
    """Close the client and the cluster, each within :data:`CLOSE_S` (never raises)."""
    for thing in (client, cluster):
        with contextlib.suppress(Exception):  # a cluster gone already, or too slow to say goodbye
            if thing is not None:
                thing.close(timeout=CLOSE_S)


def connect(address: str):
    """(None, Client) of an existing cluster at ``address``, with at least one worker."""
    from dask.distributed import Client

    try:
        c = Client(address, timeout=CONNECT_S)
    except (OSError, TimeoutError) as exc:
        raise SoilVolumeError(
            f"{opt('scheduler', address)}: cannot reach the Dask scheduler ({short_error(exc)})"
        ) from None
    except Exception as exc:  # noqa: BLE001 - whatever a server that is not a Dask scheduler makes it raise
        raise SoilVolumeError(
            f"{opt('scheduler', address)}: the server there does not speak Dask's protocol ({type(exc).__name__})"
        ) from None
    try:
        c.wait_for_workers(1, timeout=NO_WORKERS_S)
    except Exception:  # noqa: BLE001 - a timeout, or the scheduler gone meanwhile
        shut(None, c)
        raise SoilVolumeError(
            f"{opt('scheduler', address)}: the Dask cluster has no workers (none joined within {NO_WORKERS_S:.0f} s)"
        ) from None
    return None, c


def local(workers: int, processes: bool, per_worker_gb: float | None, scratch: Path, spawn: bool = False):
    """(LocalCluster, Client): ``workers`` processes of one thread (or one of ``workers`` threads),
    quiet, scratch space in ``scratch``; ``spawn``: as on Windows and macOS (the self-test)."""
    method = "spawn" if spawn else _start_method() if processes else None  # first: the forkserver's imports
    import dask
    from dask.distributed import Client, LocalCluster

    scratch.mkdir(parents=True, exist_ok=True)
    settings = {"temporary-directory": str(scratch), **QUIET}
    settings.update({f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in LOCAL_WORKER_ENV.items()})
    if method:
        settings["distributed.worker.multiprocessing-method"] = method
    with dask.config.set(settings):
        cluster = LocalCluster(
            n_workers=workers if processes else 1,
            threads_per_worker=1 if processes else workers,
            processes=processes,
            memory_limit=f"{per_worker_gb:.3f}GiB" if per_worker_gb else None,
            dashboard_address=None,
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},  # no port 8787 warning
            silence_logs=logging.CRITICAL,
            local_directory=str(scratch),
            **({"preload": [WORKER_INIT]} if processes else {}),
        )
    try:
        return cluster, Client(cluster)
    except BaseException:
        shut(cluster, None)
        raise


def _start_method() -> str | None:
    """``forkserver`` on Linux: one server process imports Dask and the tasks' modules once and
    forks each worker from it (a spawned worker imports them itself, ~0.6 s of CPU each, which on
    a small machine the driver's reading waits for). It starts before this process imports Dask
    and starts the scheduler and the nannies: its imports (~0.4 s) overlap them. None elsewhere:
    Dask's default, spawn (Windows has no fork; on macOS system libraries are not fork-safe)."""
    import multiprocessing
    from importlib.util import find_spec
    from multiprocessing import forkserver

    import dask
    import yaml

    if not sys.platform.startswith("linux") or "forkserver" not in multiprocessing.get_all_start_methods():
        return None
    multiprocessing.get_context("forkserver").set_forkserver_preload(list(FORKSERVER_PRELOAD))
    # what each nanny sets before its worker starts, the server's for all (one OpenMP/BLAS thread per worker, read
    # by C libraries as a process starts): Dask's pre-spawn-environ (the user's variables win), LOCAL_WORKER_ENV
    defaults = Path(find_spec("distributed").origin).parent / "distributed.yaml"  # Distributed not imported (0.3 s)
    dask.config.update_defaults(yaml.safe_load(defaults.read_text(encoding="utf-8")))
    env = {**(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {}), **LOCAL_WORKER_ENV}
    os.environ.update({k: os.environ.get(k, str(v)) for k, v in env.items() if v is not None})
    forkserver.ensure_running()
    from distributed.utils import get_mp_context

    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        get_mp_context()  # Dask sets its preload list on first use: for a server running already, a no-op
    return "forkserver"


def checker(hooks) -> Callable[[], None]:
    """A check for signals and for ``hooks``' cancel button that does not move the progress bar."""

    def check() -> None:
        interrupt.check()
        if hooks.cancel is not None and hooks.cancel():
            raise Cancelled("cancelled by the user")

    return check
