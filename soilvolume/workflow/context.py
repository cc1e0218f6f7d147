"""What every step of a product is given: an immutable :class:`Context`, and the progress table."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from ..core.hooks import Hooks
from ..core.outputs import OutputDir
from ..core.types import Epoch
from ..distributed.schedule import Schedule
from ..options import Options
from .timing import Timer

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


def spans(steps: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """Each step's percent range: the table's for a whole run, its share of 0-100 for a shorter one."""
    if steps == tuple(PROGRESS):
        return {s: PROGRESS[s][:2] for s in steps}
    widths = [PROGRESS[s][1] - PROGRESS[s][0] for s in steps]
    total, at, out = sum(widths), 0.0, {}
    for s, w in zip(steps, widths, strict=True):
        out[s] = (round(100 * at / total, 1), round(100 * (at + w) / total, 1))
        at += w
    return out


@dataclass(frozen=True)
class Context:
    """A product's run: epochs, options, callbacks, timer, output folder (None: one file), each step's percent
    range (:func:`spans`), ``--scheduler`` as parsed once (None: ``auto``), never its text again."""

    epochs: tuple[Epoch, ...]
    options: Options
    hooks: Hooks
    steps: tuple[str, ...]
    timer: Timer = field(default_factory=Timer)
    out: OutputDir | None = None
    spans: dict[str, tuple[float, float]] = field(default_factory=dict)
    schedule: Schedule | None = None

    def __post_init__(self) -> None:
        if not self.spans:
            object.__setattr__(self, "spans", spans(self.steps))

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
