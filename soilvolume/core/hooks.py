"""Run hooks (progress, log, cancellation) and a run's result: what every step reports through
and what the entry points return."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import interrupt
from .types import SoilVolumeError
from .wording import cli

Progress = Callable[[float, str], None]
Log = Callable[[str], None]
Cancel = Callable[[], bool]


class Cancelled(SoilVolumeError):
    """The user cancelled the run; nothing was written."""


@dataclass
class Hooks:
    """Progress, log and cancellation callbacks (all optional). A message is logged once even
    when a stage reports it many times (e.g. once per ICP level). Options in the messages are
    worded for the command line, or with ``keyed`` left as markers (:mod:`soilvolume.core.wording`)
    for a front end that words them its own way."""

    progress: Progress | None = None
    log: Log | None = None
    cancel: Cancel | None = None
    keyed: bool = False
    _last: str | None = field(default=None, repr=False)

    def step(self, percent: float, message: str, log: bool = True) -> None:
        """Check for cancellation (:class:`Cancelled`, or ``Interrupted`` after SIGINT/SIGTERM),
        move the progress bar and log ``message`` (once)."""
        interrupt.check()
        if self.cancel is not None and self.cancel():
            raise Cancelled("cancelled by the user")
        if self.progress is not None:
            self.progress(percent, message if self.keyed else cli(message))
        if log and message != self._last:
            self._last = message
            self.info(message)

    def info(self, message: str) -> None:
        if self.log is not None:
            self.log(message if self.keyed else cli(message))

    def ticker(self, start: float, end: float, message: str, expected: int = 8) -> Callable[[], None]:
        """A ``check()`` callback for a long stage of unknown length (logged by the step that
        started it): each call checks for cancellation and moves the bar from ``start`` towards
        ``end`` (about 90 % of the way after ``expected`` calls, never reaching it)."""
        calls = [0]
        rate = 0.1 ** (1.0 / max(expected, 1))

        def check() -> None:
            calls[0] += 1
            self.step(start + (end - start) * (1.0 - rate ** calls[0]), message, log=False)

        return check


@dataclass
class Result:
    """The single source of a run's numbers: ``report`` is exactly what report.json holds,
    ``outputs`` maps output names (dem_before, dem_after, difference, plane_offset,
    after_registered, report_json, report_html, ...) to written paths."""

    report: dict[str, Any]
    outputs: dict[str, Path] = field(default_factory=dict)
    keyed: dict[str, Any] | None = None  # the report with its options by key (wording.opt), for front ends

    @classmethod
    def written(cls, report: dict[str, Any], moved: dict[str, Path], keyed: dict[str, Any] | None = None) -> Result:
        """The result of a run whose output folder holds ``moved`` (file name -> path)."""
        named = {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in moved.items()}
        return cls(report, named, keyed)
