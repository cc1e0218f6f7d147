"""Tiles of a grid kept on disk between a tiled run's steps, and for the same command run again
after an interruption.

:class:`TileStore`: one ``.npy`` file per array and tile, named with the run's key
(below), written atomically, read back as any window of the grid (memory-mapped).

:class:`RunStore`: each run's own store, a hidden sibling of the output folder
(``.NAME.soilvolume-tiles-PID-TOKEN``), the Dask workers' scratch space in it; removed when the
run succeeds or fails. An interrupted run keeps its finished tiles as ``.NAME.soilvolume-tiles``,
which the next run into the folder claims (one atomic rename: one run gets it) and uses only if
they were computed from what it computes from (``store.json``), else discards, saying why.

The run's key, what its tiles were computed from, so a resume never reuses work of other inputs,
options or code: every input file's content identity, every option that changes numbers (all not
declared run control in :class:`~soilvolume.options.Options`: a new one cannot be forgotten), the
engine's source and the run's plan (grid, registration, tiling).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, fields
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..core.interrupt import Interrupted, cleanup_on_exit
from ..core.siblings import dead_siblings, remove, sibling, tag
from ..inputs.io import atomic_path
from ..inputs.vpc import read_vpc
from ..options import Options

Window = tuple[int, int, int, int]  # r0, r1, c0, c1
KEPT, MANIFEST = "soilvolume-tiles", "store.json"
# numpy parses a .npy header with ast.literal_eval; CPython 3.11 (Debian 12's 3.11.2 among them) keeps
# the AST constructor's recursion depth per interpreter, so two threads building ASTs at once can
# fail with "SystemError: AST constructor recursion depth mismatch" (python/cpython#106905): the
# tasks of a threads:N run load tiles at the same time. Their header reads take turns.
_HEADERS = threading.Lock()
WHOLE_BYTES = 16 * 2**20  # files up to this size are hashed whole
HEAD_BYTES = 64 * 1024  # else: the header and VLRs, the end (LAZ chunk table, EVLRs) ...
SAMPLES, SAMPLE_BYTES = 16, 4096  # ... and this many blocks spread over the body
FILE_OPTIONS = ("zones", "stable_mask")  # options naming files whose content matters


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
            why = difference(old, parts) if old else "they carry no record of their inputs"
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


def file_identity(path: str | os.PathLike) -> dict[str, Any]:
    """Size, modification time (ns) and a CRC-32 of ``path``'s content (whole when small, else its
    first and last :data:`HEAD_BYTES` and :data:`SAMPLES` blocks between). A change detector:
    an edit in place keeps size and time only if set back, and the CRC still catches all but one
    in 4 billion; zlib's CRC reads 3-4 GB/s, BLAKE2 under 1 GB/s (a run hashes every tile)."""
    st = os.stat(path)
    step = (st.st_size - 2 * HEAD_BYTES) // (SAMPLES + 1)
    spans = [(0, HEAD_BYTES), *((HEAD_BYTES + k * step, SAMPLE_BYTES) for k in range(1, SAMPLES + 1))]
    spans = [*spans, (st.st_size - HEAD_BYTES, HEAD_BYTES)] if st.st_size > WHOLE_BYTES else [(0, None)]
    crc = 0
    with open(path, "rb") as f:
        for at, size in spans:
            f.seek(at)
            crc = zlib.crc32(f.read(size), crc)
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns, "hash": f"crc32:{crc:08x}"}


def input_identity(path: str | os.PathLike) -> dict[str, Any]:
    """{file name: identity} of an input: the file, and for a VPC each of its tiles too."""
    p = Path(path)
    out = {str(p): file_identity(p)}
    if p.suffix.lower() == ".vpc":
        out.update({t.path: file_identity(t.path) for t in read_vpc(p).tiles})
    return out


def number_options(options: Options) -> dict[str, Any]:
    """Every option that changes the numbers (not ``run_control``), a file named by one as its identity."""
    out: dict[str, Any] = {}
    for f in fields(options):
        if f.metadata.get("run_control"):
            continue
        value = getattr(options, f.name)
        if f.name in FILE_OPTIONS and value:  # a vector file and its sidecars (a Shapefile's .dbf, ...), or a folder
            path = Path(value)
            files = path.iterdir() if path.is_dir() else (p for p in path.parent.iterdir() if p.stem == path.stem)
            value = {"path": str(value), "files": {p.name: file_identity(p) for p in sorted(files) if p.is_file()}}
        out[f.name] = value
    return out


@lru_cache(maxsize=1)
def code_identity() -> str:
    """A digest of the engine's Python sources (a changed engine computes other numbers)."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.blake2b(digest_size=16)
    for source in sorted(root.rglob("*.py")):
        digest.update(str(source.relative_to(root)).encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()


def run_parts(inputs: dict[str, Any], options: Options, plan: dict[str, Any]) -> dict[str, Any]:
    """What a run's tiles are computed from, as plain JSON values; ``inputs``: {"before": ...,
    "after": ...} of :func:`input_identity`."""
    parts = {"code": code_identity(), "inputs": inputs, "options": number_options(options), "plan": plan}
    plain = lambda v: v.tolist() if hasattr(v, "tolist") else str(v)  # noqa: E731 - numpy values as Python
    return json.loads(json.dumps(parts, default=plain))  # tuples as lists: JSON-comparable


def difference(old: dict[str, Any], new: dict[str, Any]) -> str:
    """Why the tiles of ``old`` parts cannot serve ``new`` ones, in a few words ("" when equal)."""
    if old.get("code") != new.get("code"):
        return "the engine's code changed"
    for role in ("before", "after"):
        a, b = old.get("inputs", {}).get(role, {}), new.get("inputs", {}).get(role, {})
        for name in b:
            if name not in a:
                return f"the {role} input is another set of files ({Path(name).name} is new)"
            if a[name] != b[name]:
                return f"{Path(name).name} changed (size, modification time or content)"
        if set(a) != set(b):
            return f"the {role} input is another set of files"
    o, n = old.get("options", {}), new.get("options", {})
    for key in n:
        if o.get(key) != n[key] and isinstance(n[key], dict) and isinstance(o.get(key), dict):
            return f"the --{key.replace('_', '-')} file {Path(n[key]['path']).name} changed"
        if o.get(key) != n[key]:
            return f"--{key.replace('_', '-')} differs ({_short(o.get(key))} then, {_short(n[key])} now)"
    if old.get("plan") != new.get("plan"):
        return "the registration, grid or tiling differs"
    return "" if old == new else "they were computed differently"


def _short(value: Any) -> str:
    text = json.dumps(value) if isinstance(value, dict) else str(value)
    return text if len(text) <= 40 else text[:37] + "..."
