"""Every knob of the pipeline in one dataclass, with defaults and one-line docs.

The CLI builds its ``--help`` from the ``help`` metadata here, the QGIS algorithms map their
parameters onto the same fields, so all front ends share one set of defaults.
"""

from __future__ import annotations

from dataclasses import Field, dataclass, fields, replace
from typing import Any

from .inputs import InputOptions
from .products import ProductOptions
from .registration import RegistrationOptions
from .table import COMMANDS
from .volumes import VolumeOptions

__all__ = ["COMMANDS", "Options", "command_fields"]


@dataclass(frozen=True)
class Options(ProductOptions, VolumeOptions, RegistrationOptions, InputOptions):
    """Options of one run (all lengths in metres of the before CRS). The fields are declared by
    topic, in table order, in :mod:`.inputs`, :mod:`.registration`, :mod:`.volumes` and
    :mod:`.products`; a subclass lists its bases last-first so :func:`dataclasses.fields` keeps that order."""

    def with_(self, **changes: Any) -> Options:
        """A copy with some fields changed."""
        return replace(self, **changes)


def command_fields(command: str) -> list[Field]:
    """The option fields ``command`` takes, in table order."""
    if command not in COMMANDS:
        raise ValueError(f"unknown command {command!r}")
    return [f for f in fields(Options) if command in f.metadata["commands"]]
