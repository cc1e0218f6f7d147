"""The inputs' options: CRS overrides, pipelines, what is read of each cloud."""

from __future__ import annotations

from .table import PREPARE, option, options

HELP = {
    "before_crs": "CRS of the before cloud when its header has none (e.g. EPSG:32654 or EPSG:2991+6360)",
    "after_crs": "CRS of the after cloud when its header has none",
}


@options(HELP)
class InputOptions:
    """The inputs' options: CRS overrides, pipelines, what is read of each cloud."""

    # inputs
    before_crs: str | None = option(None, "Before CRS override", PREPARE)
    after_crs: str | None = option(None, "After CRS override", PREPARE)
