"""Tiles of a grid kept on disk between a tiled run's steps, and for the same command run again
after an interruption.

:class:`TileStore`: one ``.npy`` file per array and tile, named with the run's key
(:mod:`fingerprint`), written atomically, read back as any window of the grid (memory-mapped).

:class:`RunStore`: each run's own store, a hidden sibling of the output folder
(``.NAME.soilvolume-tiles-PID-TOKEN``), the Dask workers' scratch space in it; removed when the
run succeeds or fails. An interrupted run keeps its finished tiles as ``.NAME.soilvolume-tiles``,
which the next run into the folder claims (one atomic rename: one run gets it) and uses only if
they were computed from what it computes from (``store.json``), else discards, saying why.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.interrupt import Interrupted, cleanup_on_exit
from ..core.siblings import dead_siblings, remove, sibling, tag
from ..inputs.io import atomic_path
from . import fingerprint

Window = tuple[int, int, int, int]  # r0, r1, c0, c1
KEPT, MANIFEST = "soilvolume-tiles", "store.json"
# numpy parses a .npy header with ast.literal_eval; CPython 3.11 (Debian 12's 3.11.2 among them) keeps
# the AST constructor's recursion depth per interpreter, so two threads building ASTs at once can
# fail with "SystemError: AST constructor recursion depth mismatch" (python/cpython#106905): the
# tasks of a threads:N run load tiles at the same time. Their header reads take turns.
_HEADERS = threading.Lock()


@dataclass(frozen=True)
class TileStore:
    """Per-tile arrays of a grid cut into ``windows``, files named with ``key`` (picklable: sent to
    tasks; the folder must be visible to every worker)."""

    folder: str
    windows: tuple[Window, ...]
    key: str = "tiles"

    def _file(self, name: str, win: Window) -> Path:
        return Path(self.folder) / "{}_{}_{}_{}_{}_{}.npy".format(self.key, name, *win)

    def has(self, names, win: Window) -> bool:
        """Whether the arrays ``names`` of tile ``win`` are all on disk (a finished tile)."""
        return all(self._file(n, win).exists() for n in names)

    def save(self, win: Window, arrays: dict[str, np.ndarray]) -> None:
        """Write the tile's arrays, each atomically (an interrupted task leaves no partial tile)."""
        for name, arr in arrays.items():
            with atomic_path(self._file(name, win)) as tmp, open(tmp, "wb") as f:
                np.save(f, np.ascontiguousarray(arr))

    def load(self, name: str, win: Window) -> np.ndarray:
        """The tile's array ``name``, memory-mapped (see :data:`_HEADERS`)."""
        with _HEADERS:
            return np.load(self._file(name, win), mmap_mode="r")

    def read(self, name: str, win: Window, fill=np.nan, dtype=None) -> np.ndarray:
        """The array ``name`` on any window of the grid (``fill`` where no tile covers a cell)."""
        r0, r1, c0, c1 = win
        out = None  # the tiles cover the grid: some tile meets any window of it
        for t in self.windows:
            a0, a1, b0, b1 = max(r0, t[0]), min(r1, t[1]), max(c0, t[2]), min(c1, t[3])
            if a0 < a1 and b0 < b1:
                part = self.load(name, t)[a0 - t[0] : a1 - t[0], b0 - t[2] : b1 - t[2]]
                if out is None:
                    out = np.full((r1 - r0, c1 - c0), fill, dtype or part.dtype)
                out[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0] = part
        return out


class RunStore:
    """The tile store of one run (see module): :meth:`bind` once the plan is known, then :meth:`close`."""

    def __init__(self, final: Path) -> None:
        self.final = Path(final)
        self.kept = self.final.with_name(f".{tag(self.final.name)}.{KEPT}")
        self.folder = sibling(self.final, KEPT)
        for entry, _ in dead_siblings(self.final, (KEPT,)):  # the stores of runs no longer alive (killed)
            remove(entry)
        self.claimed = False
        with contextlib.suppress(OSError):  # claim the tiles an interrupted run kept (atomic: one run gets them)
            os.rename(self.kept, self.folder)
            self.claimed = True
        if self.claimed and (self.folder.is_symlink() or not self.folder.is_dir()):  # not ours: never follow it
            self.folder.unlink()
            self.claimed = False
        if not self.claimed:
            self.folder.mkdir()
        self.scratch = self.folder / "dask"  # the workers' spill and scratch space
        self.key = ""

    def bind(self, parts: dict) -> str | None:
        """Key the store by what the run computes from, discarding another computation's tiles:
        the reason in a line for the log (None when nothing was discarded)."""
        text = json.dumps(parts, sort_keys=True, separators=(",", ":"))
        self.key = hashlib.blake2b(text.encode(), digest_size=10).hexdigest()  # 20 hex digits
        manifest = self.folder / MANIFEST
        said = None
        if self.claimed:
            try:
                old = json.loads(manifest.read_text())
            except (OSError, ValueError):
                old = {}
            why = fingerprint.difference(old, parts) if old else "they carry no record of their inputs"
            if why:
                said = f"discarding the tiles kept by an interrupted run: {why}; starting afresh"
                for entry in self.folder.iterdir():
                    if entry != self.scratch:
                        remove(entry)
        with atomic_path(manifest) as tmp:
            tmp.write_text(json.dumps(parts, sort_keys=True))
        return said

    def tiles(self, windows) -> TileStore:
        return TileStore(str(self.folder), tuple(windows), self.key)

    def close(self, keep: bool) -> bool:
        """Remove the store, or with ``keep`` (an interruption) leave its finished tiles where the
        same command finds them; whether they were kept."""
        shutil.rmtree(self.scratch, ignore_errors=True)
        for partial in self.folder.glob(".*"):  # a tile write cut short (a worker killed mid-write)
            partial.unlink(missing_ok=True)
        if keep and self.key and any(self.folder.glob(f"{self.key}_*.npy")):
            remove(self.kept)  # an older interruption's (ours is newer), or not ours: never followed
            with contextlib.suppress(OSError):
                os.rename(self.folder, self.kept)
                return True
        shutil.rmtree(self.folder, ignore_errors=True)
        return False


@contextmanager
def run_store(final: Path) -> Iterator[RunStore]:
    """The run's :class:`RunStore`, removed at the block's end, kept on an interruption (which says where)."""
    store = RunStore(final)
    try:
        with cleanup_on_exit(lambda: str(store.kept) if store.close(keep=True) else None):  # forced: out at once
            yield store
    except Interrupted as exc:
        raise Interrupted(exc.signum, kept=str(store.kept) if store.close(keep=True) else None) from None
    finally:
        store.close(keep=False)  # after keeping (renamed), nothing left to remove
