"""Per-stage wall times adding up to the process's: its start-up (imports included), each stage, the rest."""

from __future__ import annotations

import os
import time
from contextlib import contextmanager


def process_age() -> float | None:
    """Seconds since this process started (Linux: /proc; else None): the middle of its start's clock
    tick against the boot-time clock, within half a tick (/proc/uptime's truncations made two)."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime
        uptime = time.clock_gettime(time.CLOCK_BOOTTIME)  # the clock /proc's start time counts on
        return max(0.0, uptime - (start_ticks + 0.5) / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return None


class Timer:
    """Per-stage wall times (s) in the order they ran; :meth:`totals` adds ``startup`` (process start to
    this timer) and ``other`` (untimed), so they sum to the process's wall time."""

    def __init__(self) -> None:
        self.s: dict[str, float] = {}
        self.t0 = time.perf_counter()
        self.startup = process_age()
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
