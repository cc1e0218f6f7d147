"""Waiting for a Dask cluster's tasks: results as they finish, a heartbeat checking for signals,
cancellation, a lost scheduler or workers all gone; a cluster's failure one line saying what the
tasks were doing."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future

from ..core import interrupt
from ..core.types import SoilVolumeError, short_error
from ..core.wording import opt
from ..native import OFF_THE_GIL
from .cluster import NO_WORKERS_S, POLL_S


def completed(c, futures: list, what: str, check: Callable[[], None] = interrupt.check) -> Iterator:
    """The results of ``futures`` as they finish; every :data:`POLL_S`, ``check()`` (signals,
    cancellation), the connection and the workers (none for :data:`NO_WORKERS_S`: an error). A
    task's failure re-raised as it is, a cluster's as one line naming ``what`` the tasks were
    doing. No futures: nothing imported (the cluster's thread may still be importing Dask: its
    module lock would hold the driver's own scans up)."""
    pending, lonely = set(futures), None
    if not pending:
        return
    from dask.distributed import wait  # lazily: see above

    order = {f.key: k for k, f in enumerate(futures)}
    started = _workers(c)
    while pending:
        check()
        OFF_THE_GIL.set()  # the driver waits: the ahead imports may use the interpreter meanwhile
        try:
            done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        except Exception as exc:  # noqa: BLE001 - the connection broke
            raise _cluster_error(exc, what, _lost(c, started)) from None
        finally:
            OFF_THE_GIL.clear()
        for fut in sorted(done, key=lambda f: order[f.key]):
            yield _result(fut, what, lambda: _lost(c, started))
        if not done and c.status not in ("running", "connecting", "newly-created"):
            raise SoilVolumeError(f"lost the connection to the Dask scheduler while {what}")
        if done or c.scheduler_info().get("workers"):
            lonely = None
        elif time.monotonic() - (lonely := lonely or time.monotonic()) > NO_WORKERS_S:  # since it first had none
            raise SoilVolumeError(f"the Dask cluster has had no workers for {NO_WORKERS_S:.0f} s while {what}")


def in_thread(fn: Callable, *args, name: str) -> Future:
    """``fn(*args)`` on a daemon thread called ``name``: its result, or what it raised, in the future."""
    future: Future = Future()

    def run() -> None:
        try:
            future.set_result(fn(*args))
        except BaseException as exc:  # noqa: BLE001 - raised where the result is taken
            future.set_exception(exc)

    threading.Thread(target=run, daemon=True, name=name).start()
    return future


def _workers(c) -> set[str] | None:
    """The addresses of the cluster's workers (None when the scheduler does not answer)."""
    try:
        return set(c.nthreads())
    except Exception:  # noqa: BLE001 - a broken connection is reported by the caller
        return None


def _lost(c, started: set[str] | None) -> tuple[int, int]:
    """(workers of ``started`` gone since, how many there were)."""
    now = _workers(c)
    return (len(started - now), len(started)) if started and now is not None else (0, 0)


def _result(fut, what: str, lost: Callable[[], tuple[int, int]]):
    try:
        value = fut.result()
    except Exception as exc:  # noqa: BLE001 - a task's own error (SoilVolumeError, MemoryError, ...) as it is
        if type(exc).__module__.split(".")[0] in ("distributed", "concurrent", "asyncio"):
            raise _cluster_error(exc, what, lost()) from None
        raise
    fut.release()
    return value


def _cluster_error(exc: BaseException, what: str, lost: tuple[int, int] = (0, 0)) -> SoilVolumeError:
    """A cluster's failure as one line (a pending signal first: Ctrl-C stops workers too); tasks
    cancelled with a dead worker's data said as its death (``lost``: workers gone, of how many)."""
    interrupt.check()
    name = type(exc).__name__
    advice = f"give each worker more with {opt('memory_limit')}, or smaller tiles with {opt('tile_cells')}"
    if name == "KilledWorker":
        return SoilVolumeError(f"Dask workers died running the same task while {what} (out of memory? {advice})")
    if lost[0] and "Cancelled" in name:
        return SoilVolumeError(
            f"{lost[0]} of the {lost[1]} Dask workers died while {what} (killed, or out of memory? {advice})"
        )
    if "Cancelled" in name or "CommClosed" in name or isinstance(exc, OSError):
        return SoilVolumeError(f"the Dask cluster stopped the run's tasks while {what} ({name})")
    return SoilVolumeError(f"the Dask cluster failed while {what} ({name}: {short_error(exc)})")
