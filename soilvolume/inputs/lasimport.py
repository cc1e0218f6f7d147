"""laspy, imported when a LAS/LAZ file is first read (a heavy third-party import left to the
commands that read one)."""

from __future__ import annotations


def laspy_module():
    """The ``laspy`` module."""
    import laspy

    return laspy
