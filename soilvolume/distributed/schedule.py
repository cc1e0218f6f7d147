"""Where a run's work goes (``--scheduler``): in-process, on threads, on a Dask LocalCluster of
worker processes, or on an existing Dask cluster; ``auto`` keeps pairs that fit the memory
budget (``--memory-limit``) in-process and sends larger ones to a LocalCluster."""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from ..core.types import SoilVolumeError

BASE_GB = 0.45  # in-process run of a small pair: imports, registration, rasters (measured 330-460 MB)
MAX_WORKERS = 1024  # threads or worker processes of threads:N / local:N
BYTES_PER_POINT = 30.0  # in-process growth per input point (measured ~26 B from 16 M to 64 M points)


@dataclass(frozen=True)
class Schedule:
    """A parsed ``--scheduler``: kind is none, threads, local or tcp."""

    kind: str
    workers: int = 1
    address: str | None = None

    def __str__(self) -> str:
        return {"none": "none", "tcp": str(self.address)}.get(self.kind, f"{self.kind}:{self.workers}")


def parse(spec: str) -> Schedule | None:
    """``none``, ``threads[:N]``, ``local[:N]``, ``tcp://HOST:PORT`` (None for ``auto``)."""
    spec = (spec or "auto").strip()
    if spec == "auto":
        return None
    if spec == "none":
        return Schedule("none")
    if spec.startswith("tcp://") or spec.startswith("tls://"):
        return Schedule("tcp", address=spec)
    m = re.fullmatch(r"(threads|local)(?::(\d+))?", spec)
    if not m or (m.group(2) is not None and not 1 <= int(m.group(2)) <= MAX_WORKERS):
        raise SoilVolumeError(
            f"--scheduler {spec}: expected none, threads[:N], local[:N] (N from 1 to {MAX_WORKERS}), "
            "tcp://HOST:PORT or auto"
        )
    return Schedule(m.group(1), int(m.group(2) or (os.cpu_count() or 1)))


def budget_gb(memory_limit: float) -> float:
    """The memory budget in GB: ``memory_limit``, else half of this machine's memory."""
    if memory_limit > 0:
        return float(memory_limit)
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX
        try:
            import psutil

            total = psutil.virtual_memory().total
        except ImportError:
            total = 8 * 2**30
    return total / 2**30 / 2


def can_spawn() -> bool:
    """Whether worker processes can be started: this process runs a Python interpreter (inside
    QGIS, ``sys.executable`` is QGIS itself and spawned workers would start QGIS)."""
    return Path(sys.executable).name.lower().startswith("python")


def has_dask() -> bool:
    """Whether dask.distributed can be imported (``auto`` runs in-process without it)."""
    import importlib.util

    try:
        return importlib.util.find_spec("distributed") is not None
    except (ImportError, ValueError):
        return False


def in_process_gb(points: int) -> float:
    """Expected peak memory (GB) of an in-process run over ``points`` input points."""
    return BASE_GB + BYTES_PER_POINT * points / 2**30


def choose(spec: str, memory_limit: float, points: int) -> Schedule:
    """The schedule of a run over ``points`` input points (``auto`` resolved)."""
    chosen = parse(spec)
    if chosen is not None:
        return chosen
    if in_process_gb(points) <= budget_gb(memory_limit) or not has_dask():
        return Schedule("none")
    return Schedule("local" if can_spawn() else "threads", os.cpu_count() or 1)


@contextmanager
def client(schedule: Schedule, memory_limit: float) -> Iterator:
    """A future of a ``dask.distributed.Client`` for ``schedule``, started in the background
    (threads: in this process; local: a LocalCluster sharing the memory budget among its worker
    processes), closed on exit."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool, _client(schedule, memory_limit, pool) as fut:
        yield fut


@contextmanager
def _client(schedule: Schedule, memory_limit: float, pool) -> Iterator:
    fut = pool.submit(_start, schedule, memory_limit)
    try:
        yield fut
    finally:
        try:
            cluster, c = fut.result()
        except Exception:
            cluster = c = None
        if c is not None:
            c.close()
        if cluster is not None:
            cluster.close()


def _start(schedule: Schedule, memory_limit: float):
    """(LocalCluster or None, Client) for ``schedule``."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a dependency
        raise SoilVolumeError(f"--scheduler {schedule}: needs dask[distributed] ({exc})") from exc
    if schedule.kind == "tcp":
        try:
            return None, Client(schedule.address, timeout="20s")
        except OSError as exc:
            raise SoilVolumeError(f"--scheduler {schedule.address}: cannot reach the Dask scheduler ({exc})") from exc
    processes = schedule.kind == "local"
    if processes and not can_spawn():
        raise SoilVolumeError(
            f"--scheduler {schedule}: cannot start worker processes from {sys.executable}; "
            "use threads[:N] or an existing cluster (tcp://HOST:PORT)"
        )
    per_worker = budget_gb(memory_limit) / schedule.workers
    cluster = LocalCluster(
        n_workers=schedule.workers if processes else 1,
        threads_per_worker=1 if processes else schedule.workers,
        processes=processes,
        memory_limit=f"{per_worker:.3f}GiB" if processes else None,
        dashboard_address=None,
        silence_logs=40,
    )
    return cluster, Client(cluster)


def worker_gb(schedule: Schedule, memory_limit: float) -> float:
    """The memory (GB) one task may use: the budget shared by the workers (or threads)."""
    return budget_gb(memory_limit) / max(1, schedule.workers)
