"""Run hooks (progress, log, cancellation) and a run's result."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import interrupt
from .types import SoilVolumeError
from .wording import cli


class Cancelled(SoilVolumeError):
    """The user cancelled the run; nothing was written."""


@dataclass
class Hooks:
    """Optional progress, log and cancellation callbacks; a message is logged once however often a stage
    reports it; options in it worded as flags, or with ``keyed`` left as markers (:mod:`.wording`)."""

    progress: Callable[[float, str], None] | None = None
    log: Callable[[str], None] | None = None
    cancel: Callable[[], bool] | None = None
    keyed: bool = False
    _last: str | None = field(default=None, repr=False)

    def step(self, percent: float, message: str, log: bool = True) -> None:
        """Check for cancellation (:class:`Cancelled`, ``Interrupted``), move the bar, log ``message`` once."""
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

    def ticker(self, start: float, end: float, message: str) -> Callable[[], None]:
        """A ``check()`` callback of a long stage: each call checks for cancellation and moves the bar from
        ``start`` towards ``end`` (90 % of the way after 8 calls, never reaching it)."""
        calls, rate = [0], 0.1 ** (1.0 / 8)

        def check() -> None:
            calls[0] += 1
            self.step(start + (end - start) * (1.0 - rate ** calls[0]), message, log=False)

        return check


@dataclass
class Result:
    """A run's numbers: ``report`` as report.json holds it, ``outputs`` each output's name
    (dem_before, ..., report_json) and path."""

    report: dict[str, Any]
    outputs: dict[str, Path] = field(default_factory=dict)
    keyed: dict[str, Any] | None = None  # the report with its options by key (wording.opt), for front ends

    @classmethod
    def written(cls, report: dict[str, Any], moved: dict[str, Path], keyed: dict[str, Any] | None = None) -> Result:
        """The result of a run whose output folder holds ``moved`` (file name -> path)."""
        named = {n.replace(".", "_") if n.startswith("report.") else Path(n).stem: p for n, p in moved.items()}
        return cls(report, named, keyed)
