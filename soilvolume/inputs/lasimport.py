"""laspy, imported without ``requests``: laspy imports it for reading COPC over HTTP, which the
engine never does (it reads local files), and it costs ~60 ms of every run's start-up."""

from __future__ import annotations

import sys

from ..core.leanimport import without


def laspy_module():
    """The ``laspy`` module; on first import ``requests`` is hidden from it (its HTTP COPC reader
    then says requests is missing), unless something imported ``requests`` already."""
    if "laspy" not in sys.modules:
        with without(("requests",)):
            import laspy
    import laspy

    return laspy
