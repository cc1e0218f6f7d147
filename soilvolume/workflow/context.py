"""What every step of a product is given: an immutable :class:`Context`, the progress table, and the
:class:`Timer`: per-stage wall times adding up to the process's: its start-up (imports included), each stage,
the rest."""

from __future__ import annotations

import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..core.types import Epoch
from ..distributed.schedule import Schedule
from ..options import Options

#: step -> (start %, end %, message) of an estimate; a shorter product spreads its steps over 0-100
PROGRESS: dict[str, tuple[float, float, str]] = {
    "prepare": (2, 15, "reading {epochs}"),
    "register": (15, 55, "registering the after cloud onto the before cloud (coarse, then fine)"),
    "grid": (55, 70, "gridding the average heights"),
    "planes": (70, 75, "estimating the vertical bias correction"),  # or none: steps.correction_message
    "volume": (75, 85, "computing the difference and volumes"),
    "write": (85, 97, "writing outputs"),
    "report": (97, 100, "writing the report"),
}
PAIR = tuple(PROGRESS)  # the steps of a pair, in order


class Timer:
    """Per-stage wall times (s) in the order they ran; :meth:`totals` adds ``startup`` (process start to
    this timer) and ``other`` (untimed), so they sum to the process's wall time."""

    def __init__(self) -> None:
        self.s: dict[str, float] = {}
        self.t0 = time.perf_counter()
        self.startup = None  # s since this process started (Linux: /proc): the middle of its start's clock tick
        try:  # against the boot-time clock, within half a tick (/proc/uptime's truncations made two)
            with open("/proc/self/stat", encoding="ascii") as f:
                start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime
            uptime = time.clock_gettime(time.CLOCK_BOOTTIME)  # the clock /proc's start time counts on
            self.startup = max(0.0, uptime - (start_ticks + 0.5) / os.sysconf("SC_CLK_TCK"))
        except (OSError, ValueError, IndexError, AttributeError):
            pass
        self._open: dict[str, float] = {}
        self._inner: dict[str, float] = {}  # of each open stage: the time of the stages timed within it

    @contextmanager
    def __call__(self, name: str):
        """Time the stage ``name``, less the stages timed within it (``cluster_wait`` in ``crop``)."""
        outer = next(reversed(self._open), None)
        t0 = self._open[name] = time.perf_counter()
        try:
            yield
        finally:
            del self._open[name]
            took = time.perf_counter() - t0
            self.s[name] = self.s.get(name, 0.0) + took - self._inner.pop(name, 0.0)
            if outer is not None and outer in self._open:
                self._inner[outer] = self._inner.get(outer, 0.0) + took

    def totals(self) -> dict[str, float]:
        """The stages so far, with ``startup`` first and ``other`` last."""
        now = time.perf_counter()
        out = {} if self.startup is None else {"startup": self.startup}
        out.update(self.s)
        for name, t0 in self._open.items():  # a stage still running (the report's)
            out[name] = out.get(name, 0.0) + now - t0 - self._inner.get(name, 0.0)
        timed = sum(out.values()) - out.get("startup", 0.0)
        out["other"] = max(0.0, now - self.t0 - timed)
        return out


@dataclass(frozen=True)
class Context:
    """A product's run: epochs, options, callbacks, timer, output folder (None: one file), each step's percent
    range, ``--scheduler`` as parsed once (None: ``auto``), never its text again."""

    epochs: tuple[Epoch, ...]
    options: Options
    hooks: Hooks
    steps: tuple[str, ...]
    timer: Timer = field(default_factory=Timer)
    out: OutputDir | None = None
    spans: dict[str, tuple[float, float]] = field(default_factory=dict)
    schedule: Schedule | None = None

    def __post_init__(self) -> None:
        if self.spans:  # given; else the table's for a whole run, each step's share of 0-100 for a shorter one
            return
        widths = [PROGRESS[s][1] - PROGRESS[s][0] for s in self.steps]
        total, at, out = sum(widths), 0.0, {}
        for s, w in zip(self.steps, widths, strict=True):
            out[s] = (round(100 * at / total, 1), round(100 * (at + w) / total, 1))
            at += w
        object.__setattr__(self, "spans", {s: PROGRESS[s][:2] for s in PAIR} if self.steps == PAIR else out)

    def at(self, step: str, fraction: float = 0.0) -> float:
        """The percent ``fraction`` of the way through ``step``."""
        lo, hi = self.spans[step]
        return lo + (hi - lo) * fraction

    def message(self, step: str) -> str:
        """The progress table's message of ``step``, naming the run's epochs."""
        return PROGRESS[step][2].format(epochs=" and ".join(e.name for e in self.epochs))


def threads(options: Options) -> None:
    """``--threads`` (of the commands taking it) as OMP_NUM_THREADS for OpenMP libraries (Open3D 0.19+ runs
    on oneTBB: :func:`soilvolume.registration.o3d.limit_threads`; BLAS: :func:`soilvolume.process.one_blas_thread`)."""
    if options.threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(options.threads))
