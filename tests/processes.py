"""Processes of a run seen from the tests (Linux /proc): shared by the engine's and QGIS's signal tests."""

from __future__ import annotations

from pathlib import Path


def group_alive(pgid: int) -> list[int]:
    """Processes of the process group ``pgid`` still alive (a run and any worker of it)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(stat.parent.name))
    return alive
