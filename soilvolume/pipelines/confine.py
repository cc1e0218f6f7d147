"""Writers of users' pipelines never touch an input nor write outside the run's output: within a
run (:func:`writers_into`) each goes into its staging folder under its file name (committed or
removed with the outputs); a writer onto an input (symlinks, ``..`` resolved) is refused."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.types import SoilVolumeError


@dataclass
class _Run:
    folder: Path
    inputs: set[Path]
    reserved: set[str]
    used: set[str] = field(default_factory=set)


_run: ContextVar[_Run | None] = ContextVar("soilvolume_pipeline_writers", default=None)


@contextmanager
def writers_into(
    folder: Path, inputs: Iterable[str | os.PathLike | None], reserved: Iterable[str] = ()
) -> Iterator[None]:
    """Redirect pipeline writers into ``folder`` while the block runs; ``reserved`` names (the
    run's own outputs) and ``inputs`` may not be written."""
    token = _run.set(_Run(Path(folder), {Path(p).resolve() for p in inputs if p}, set(reserved)))
    try:
        yield
    finally:
        _run.reset(token)


def _refuse(source: str, i: int, kind: str, why: str) -> SoilVolumeError:
    return SoilVolumeError(f"pipeline {source}: stage {i + 1} ({kind}) {why}")


def confine_writers(stages: list[dict[str, Any]], source: str) -> list[dict[str, Any]]:
    """``stages`` with every writer confined (see the module doc); raises naming the stage."""
    run = _run.get()
    readers = {
        Path(s["filename"]).resolve()
        for s in stages
        if str(s.get("type", "")).startswith("readers.") and isinstance(s.get("filename"), str)
    }
    inputs = readers | (run.inputs if run else set())
    out = []
    for i, stage in enumerate(stages):
        kind = str(stage.get("type", ""))
        name = stage.get("filename")
        if not kind.startswith("writers.") or not isinstance(name, str):
            out.append(stage)
            continue
        target = Path(name).resolve()
        if target in inputs:
            raise _refuse(source, i, kind, f"would overwrite the input {target}; inputs are read-only")
        if run is not None:
            base = Path(name).name
            if base in ("", ".", ".."):
                raise _refuse(source, i, kind, f"has no file name in '{name}'")
            if base in run.reserved or base in run.used or (run.folder / base).resolve() in inputs:
                raise _refuse(source, i, kind, f"writes '{base}', a name the run already uses; rename it")
            run.used.add(base)
            stage = {**stage, "filename": str(run.folder / base)}
        out.append(stage)
    return out
