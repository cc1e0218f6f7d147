"""Tiles of a grid kept on disk between the steps of a tiled run: one ``.npy`` file per array
and tile, written atomically by the task that computed it, read back as any window of the
grid (memory-mapped: a window costs what it holds, not what its tiles hold)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

Window = tuple[int, int, int, int]  # r0, r1, c0, c1


@dataclass(frozen=True)
class TileStore:
    """A folder of per-tile arrays of a grid cut into ``windows`` (picklable: sent to tasks; the
    folder must be visible to every worker)."""

    folder: str
    windows: tuple[Window, ...]

    def _file(self, name: str, win: Window) -> Path:
        return Path(self.folder) / "{}_{}_{}_{}_{}.npy".format(name, *win)

    def has(self, names, win: Window) -> bool:
        """Whether every array of ``names`` of tile ``win`` is on disk (a finished tile)."""
        return all(self._file(n, win).exists() for n in names)

    def save(self, win: Window, arrays: dict[str, np.ndarray]) -> None:
        """Write the tile's arrays (each atomically: an interrupted task leaves no partial tile)."""
        for name, arr in arrays.items():
            final = self._file(name, win)
            tmp = final.with_name(f".{final.name}")
            with open(tmp, "wb") as f:
                np.save(f, np.ascontiguousarray(arr))
            tmp.replace(final)

    def load(self, name: str, win: Window) -> np.ndarray:
        return np.load(self._file(name, win), mmap_mode="r")

    def read(self, name: str, win: Window, fill=np.nan, dtype=None) -> np.ndarray:
        """The array ``name`` on any window of the grid, from the tiles meeting it (``fill``
        where no tile covers a cell)."""
        r0, r1, c0, c1 = win
        out = None
        for t in self.windows:
            a0, a1 = max(r0, t[0]), min(r1, t[1])
            b0, b1 = max(c0, t[2]), min(c1, t[3])
            if a0 >= a1 or b0 >= b1:
                continue
            part = self.load(name, t)[a0 - t[0] : a1 - t[0], b0 - t[2] : b1 - t[2]]
            if out is None:
                out = np.full((r1 - r0, c1 - c0), fill, dtype or part.dtype)
            out[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0] = part
        if out is None:
            out = np.full((r1 - r0, c1 - c0), fill, dtype or float)
        return out
