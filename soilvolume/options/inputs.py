"""The inputs' options: CRS overrides, pipelines, what is read of each cloud."""

from __future__ import annotations

from dataclasses import dataclass

from .table import PREPARE, option


@dataclass(frozen=True)
class InputOptions:
    """The inputs' options: CRS overrides, pipelines, what is read of each cloud."""

    # inputs
    before_crs: str | None = option(
        None,
        "CRS of the before cloud when its header has none (e.g. EPSG:32654 or EPSG:2991+6360)",
        label="Before CRS override",
        commands=PREPARE,
    )
    after_crs: str | None = option(
        None, "CRS of the after cloud when its header has none", label="After CRS override", commands=PREPARE
    )
