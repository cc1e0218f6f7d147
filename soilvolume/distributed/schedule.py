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
from functools import partial
from pathlib import Path
from typing import Literal

from ..core.types import SoilVolumeError
from ..core.wording import opt
from ..inputs.io import LAS_SUFFIXES
from ..inputs.stream import open_source
from . import cluster
from .cluster import START_S, Starting

BASE_GB = 0.45  # in-process run of a small pair: imports, registration, rasters (measured 330-460 MB)
MAX_WORKERS = 1024  # threads or worker processes of threads:N / local:N
BYTES_PER_POINT = 30.0  # in-process growth per input point (measured ~26 B from 16 M to 64 M points)
# a task's peak per point of its tile (both epochs, ids, sort keys, chunk): measured 22 B (a
# 73 M-point tile of the 256 M-point VPC pair peaked at 1.6 GB), counted twice over
TILE_BYTES_PER_POINT = 48.0
WORKER_MIN_GB = 0.25  # a worker process: the interpreter, numpy, laspy and a small tile
#: open files a LocalCluster's driver holds: the scheduler, a nanny and a worker's connections each
#: (it failed to start below 48 for 2 workers, 72 for 4; Dask then spins on accept() for minutes)
FILES_BASE, FILES_PER_WORKER = 32, 12
MAX_TILES = 50_000  # tasks per step a cluster schedules well (each tile is a task of each step)
EXPECTED = f"expected none, threads[:N], local[:N] (N from 1 to {MAX_WORKERS}), tcp://HOST:PORT or auto"
DEFAULT_PORT = 8786  # Dask's scheduler port


@dataclass(frozen=True)
class Schedule:
    """A parsed ``--scheduler``: in-process (none), tiles on threads, on a LocalCluster of worker
    processes (local), or on an existing cluster (tcp); ``str`` gives report.json's value."""

    kind: Literal["none", "threads", "local", "tcp"]
    workers: int = 1
    address: str | None = None

    @property
    def in_process(self) -> bool:
        """Whether the run keeps whole clouds in this process (``none``): no tiles, no cluster."""
        return self.kind == "none"

    def __str__(self) -> str:
        return {"none": "none", "tcp": str(self.address)}.get(self.kind, f"{self.kind}:{self.workers}")


class BadSchedule(SoilVolumeError):
    """A ``--scheduler`` value :func:`parse` refuses; ``problem`` says what is wrong with it."""

    def __init__(self, spec: str, problem: str) -> None:
        self.problem = problem
        super().__init__(f"{opt('scheduler', spec)}: {problem}")


def parse(spec: str) -> Schedule | None:
    """``none``, ``threads[:N]``, ``local[:N]``, ``tcp://HOST[:PORT]`` (None for ``auto``), parsed
    once per run (:func:`soilvolume.validate.schedule_of`); a :class:`BadSchedule` when wrong."""
    spec = (spec or "auto").strip()
    if spec == "auto":
        return None
    if spec == "none":
        return Schedule("none")
    if "://" not in spec:
        m = re.fullmatch(r"(threads|local)(?::(\d+))?", spec)
        if not m or (m.group(2) is not None and not 1 <= int(m.group(2)) <= MAX_WORKERS):
            raise BadSchedule(spec, EXPECTED)
        return Schedule(m.group(1), int(m.group(2) or (os.cpu_count() or 1)))
    from urllib.parse import urlsplit  # a Dask scheduler's address tcp://HOST:PORT (port 8786 when not given)

    scheme = spec.split("://", 1)[0].lower()
    if scheme == "tls":
        raise BadSchedule(
            spec, "TLS clusters need certificates, which this command does not take; use tcp:// (e.g. over a tunnel)"
        )
    if scheme != "tcp":
        raise BadSchedule(spec, f"unsupported protocol '{scheme}://'; {EXPECTED}")
    port_range = "the port must be a number from 1 to 65535"
    try:
        url = urlsplit(spec)
        port = url.port
    except ValueError:
        raise BadSchedule(spec, port_range) from None
    if not url.hostname:
        raise BadSchedule(spec, "no host: expected tcp://HOST:PORT")
    if url.path not in ("", "/") or url.query or url.fragment or url.username or url.password:
        raise BadSchedule(spec, "expected tcp://HOST:PORT, nothing more")
    if port is not None and not 1 <= port <= 65535:
        raise BadSchedule(spec, port_range)
    host = f"[{url.hostname}]" if ":" in url.hostname else url.hostname
    return Schedule("tcp", address=f"tcp://{host}:{port or DEFAULT_PORT}")


def budget_gb(memory_limit: float) -> float:
    """The memory budget in GB: ``memory_limit``, else half of this machine's memory."""
    if memory_limit > 0:
        return float(memory_limit)
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX
        import psutil  # a dependency; lazily: 16 ms

        total = psutil.virtual_memory().total
    return total / 2**30 / 2


def can_spawn() -> bool:
    """Whether this process runs a Python interpreter that can start worker processes (inside
    QGIS, ``sys.executable`` is QGIS itself and spawned workers would start QGIS)."""
    return Path(sys.executable).name.lower().startswith("python")


def has_dask() -> bool:
    """Whether dask.distributed can be imported (``auto`` runs in-process without it)."""
    import importlib.util

    return importlib.util.find_spec("distributed") is not None


def choose(memory_limit: float, points: int) -> Schedule:
    """What ``auto`` picks for ``points`` input points: in-process when their expected peak fits
    the memory budget (or without Dask), else a LocalCluster (threads when processes cannot start)."""
    if BASE_GB + BYTES_PER_POINT * points / 2**30 <= budget_gb(memory_limit) or not has_dask():
        return Schedule("none")
    workers = os.cpu_count() or 1
    return Schedule("local" if can_spawn() and open_files_short(workers) is None else "threads", workers)


def open_files_short(workers: int) -> tuple[int, int] | None:
    """(the open-file limit, the files a LocalCluster of ``workers`` processes needs) when the limit
    is below that; None when it is not (or there is no such limit: Windows)."""
    try:
        import resource
    except ImportError:
        return None
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    need = FILES_BASE + FILES_PER_WORKER * workers
    return (soft, need) if soft != resource.RLIM_INFINITY and soft < need else None


def check_local(schedule: Schedule, memory_limit: float) -> None:
    """Refuse, before Dask starts it, a LocalCluster whose workers' budget share is below what one
    needs to start and hold a tile (below it Dask pauses or restarts workers for ever), or that
    the open-file limit (``ulimit -n``) cannot hold."""
    if schedule.kind != "local":
        return
    n = schedule.workers
    per_worker = budget_gb(memory_limit) / n
    share = f"{per_worker:.3g} GB for each of the {n} worker processes of {schedule}"
    if per_worker < WORKER_MIN_GB and memory_limit <= 0:
        raise SoilVolumeError(
            f"{opt('scheduler', schedule)}: {share} (half of this machine's memory), below the {WORKER_MIN_GB:g} GB a "
            "worker needs; use fewer workers"
        )
    if per_worker < WORKER_MIN_GB:
        raise SoilVolumeError(
            f"{opt('memory_limit', f'{memory_limit:g}')}: {share}, below the {WORKER_MIN_GB:g} GB a worker needs "
            f"(give at least {WORKER_MIN_GB * n:g}, or 0 for half of this machine's memory)"
        )
    short = open_files_short(n)
    if short is not None:
        raise SoilVolumeError(
            f"{opt('scheduler', schedule)}: the open-file limit (ulimit -n) is {short[0]}, below the "
            f"{short[1]} a Dask cluster of {n} worker processes needs; raise it (e.g. "
            f"ulimit -n {max(1024, short[1])}) or run in-process ({opt('scheduler', 'none')})"
        )


def check_tiles(windows: list, points_per_cell: float, task_gb: float, options) -> None:
    """Refuse tilings a cluster cannot run: more than :data:`MAX_TILES` tiles, or a largest tile
    whose points do not fit half of a task's memory share (``--memory-limit``)."""
    given = opt("tile_cells", options.tile_cells) if options.tile_cells else opt("memory_limit")
    if len(windows) > MAX_TILES:
        raise SoilVolumeError(
            f"{given}: {len(windows):,} tiles, more than the {MAX_TILES:,} tasks a cluster schedules well; "
            f"use larger tiles ({opt('tile_cells')}) or 0 for tiles from the point density"
        )
    cells = max((w[1] - w[0]) * (w[3] - w[2]) for w in windows)
    need = cells * points_per_cell * TILE_BYTES_PER_POINT * 2 / 2**30  # a task may use half of its share
    if need > task_gb:
        fix = f"a smaller {opt('tile_cells')} or a larger budget" if options.tile_cells else "a larger budget"
        raise SoilVolumeError(
            f"{given}: {task_gb:.3g} GB per task ({opt('memory_limit', f'{options.memory_limit:g}')}) "
            f"cannot hold a tile of {cells:,} cells of this pair ({cells * points_per_cell:,.0f} points need "
            f"{need:.3g} GB); give {fix}"
        )


@contextmanager
def client(schedule: Schedule, memory_limit: float, scratch: Path) -> Iterator[Starting]:
    """A :class:`cluster.Starting` of the Dask client of ``schedule`` (a LocalCluster's workers share
    the budget, their scratch space in ``scratch``), shut on exit."""
    check_local(schedule, memory_limit)
    start = partial(_start, schedule, memory_limit, scratch)
    starting = Starting(start, str(schedule), START_S[schedule.kind], here=schedule.kind != "tcp")
    try:
        yield starting
    finally:
        starting.close()


def _start(schedule: Schedule, memory_limit: float, scratch: Path):
    """(LocalCluster or None, Client) for ``schedule``."""
    if not has_dask():  # pragma: no cover - a dependency
        raise SoilVolumeError(
            f"{opt('scheduler', schedule)}: needs dask[distributed] (pip install 'dask[distributed]')"
        )
    if schedule.kind == "tcp":
        return cluster.connect(str(schedule.address))
    processes = schedule.kind == "local"
    if processes and not can_spawn():
        raise SoilVolumeError(
            f"{opt('scheduler', schedule)}: cannot start worker processes from {sys.executable}; "
            "use threads[:N] or an existing cluster (tcp://HOST:PORT)"
        )
    per_worker = budget_gb(memory_limit) / schedule.workers if processes else None
    return cluster.local(schedule.workers, processes, per_worker, scratch)


def schedule_for(chosen: Schedule | None, before, after, options, pipeline: bool) -> Schedule:
    """The parsed ``--scheduler`` (``chosen``), or for ``auto`` (None) :func:`choose` by the LAS/COPC/VPC
    headers' points; pipelines and other formats in-process."""
    if chosen is None:
        if pipeline or any(Path(p).suffix.lower() not in LAS_SUFFIXES | {".vpc"} for p in (before, after)):
            return Schedule("none")
        return choose(options.memory_limit, sum(open_source(p).count for p in (before, after)))
    if pipeline and not chosen.in_process:
        raise SoilVolumeError(
            f"{opt('scheduler', options.scheduler)}: preparation pipelines run in-process only "
            f"(use {opt('scheduler', 'none')})"
        )
    return chosen
