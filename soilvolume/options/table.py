"""How an option of the table (:class:`soilvolume.options.Options`) is declared."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

ESTIMATE = ("estimate",)  # the commands that take an option unless it says otherwise


def option(
    default: Any,
    label: str,
    commands: tuple[str, ...] = ESTIMATE,
    unit: str | None = None,
    lo: float | None = None,
    hi: float | None = None,
    *,
    choices: tuple | None = None,
    lo_open: bool = False,
    run_control: bool = False,
    help: str | None = None,
) -> Any:
    """An option: default, GUI ``label``, the ``commands`` taking it, ``unit``, range ``lo``..``hi`` (``lo`` excluded
    when ``lo_open``), ``choices``, ``help`` (or from :func:`options`) and ``run_control``: where and how the run
    goes, never its numbers (every other option keys the work a resumed run may reuse)."""
    meta = {"help": help, "choices": choices, "label": label, "unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open}
    return field(default=default, metadata={**meta, "commands": commands, "run_control": run_control})


def options(helps: dict[str, str]) -> Callable[[type], type]:
    """A frozen dataclass of :func:`option` fields, each with its help from ``helps`` (by name; one each)."""

    def make(cls: type) -> type:
        if helps.keys() != cls.__annotations__.keys():
            raise TypeError(f"{cls.__name__}: the help texts do not match the fields")
        for name, text in helps.items():
            f = getattr(cls, name)
            setattr(cls, name, field(default=f.default, metadata={**f.metadata, "help": text}))
        return dataclass(frozen=True)(cls)

    return make
