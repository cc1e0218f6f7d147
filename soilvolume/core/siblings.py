"""An output's hidden siblings (``.<name>.<kind>-<pid>-<token>``: staging, the old set, a tile store),
removed when their run is dead, and the lock concurrent runs swap and sweep under."""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import shutil
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .types import SoilVolumeError

try:
    import fcntl
except ImportError:  # Windows: no flock; a lock folder made atomically takes its place
    fcntl = None

STAGING, TRASH = "soilvolume-staging", "soilvolume-trash"
NAME_MAX = 255


def tag(name: str) -> str:
    """``name``, or a short digest of it when hidden siblings would exceed NAME_MAX bytes."""
    if len(name.encode()) <= NAME_MAX - 40:
        return name
    return hashlib.sha1(name.encode()).hexdigest()[:16]


def sibling(final: Path, kind: str, pid: int | None = None, suffix: str = "", token: str | None = None) -> Path:
    """The hidden sibling of ``final`` of this ``kind`` for process ``pid`` (this one) and ``token`` (random)."""
    token = secrets.token_hex(4) if token is None else token
    return final.with_name(f".{tag(final.name)}.{kind}-{pid or os.getpid()}-{token}{suffix}")


def _alive(pid: int) -> bool:
    import psutil  # os.kill(pid, 0) is a Ctrl-C event on Windows; lazily: 16 ms, only when a sibling is found

    return pid == os.getpid() or psutil.pid_exists(pid)


def remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def dead_siblings(final: Path, kinds: Iterable[str]) -> Iterator[tuple[Path, str]]:
    """(path, kind) of the hidden siblings of ``final`` of these ``kinds`` whose run is dead."""
    name, kind = re.escape(tag(final.name)), "|".join(map(re.escape, kinds))
    for entry, m in _dead(final.parent, rf"^\.{name}\.(?P<kind>{kind})-(?P<pid>\d+)(-\w*)?(\..*)?$"):
        yield entry, m["kind"]


def _dead(folder: Path, pattern: str) -> Iterator[tuple[Path, re.Match]]:
    """The entries of ``folder`` matching ``pattern`` whose run (its ``pid`` group) is dead."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        m = re.match(pattern, entry.name)
        if m and not _alive(int(m["pid"])):
            yield entry, m


def sweep(final: Path) -> None:
    """Remove dead runs' hidden siblings of ``final``; a trashed old set whose new one never came is put back."""
    for entry, kind in dead_siblings(final, (STAGING, TRASH)):
        if kind == TRASH and not final.exists():
            os.rename(entry, final)
        else:
            remove(entry)


def sweep_inside(folder: Path) -> None:
    """Remove staging folders dead runs left inside ``folder`` (mount points, folders whose parent is not writable)."""
    for entry, _ in _dead(folder, rf"^\.{STAGING}-(?P<pid>\d+)-\w+$") if folder.is_dir() else ():
        remove(entry)


LOCK_DIR, LOCK_WAIT_S = ".soilvolume-lock", 120.0


@contextmanager
def locked(folder: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``folder``: ``flock`` on POSIX, else :func:`_lock_folder`."""
    if fcntl is None:
        with _lock_folder(folder):
            yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


@contextmanager
def _lock_folder(folder: Path, wait_s: float = LOCK_WAIT_S) -> Iterator[None]:
    """Without ``flock`` (Windows): a folder ``.soilvolume-lock`` made atomically inside ``folder``, waited
    for ``wait_s`` at most."""
    lock, deadline = folder / LOCK_DIR, time.monotonic() + wait_s
    while True:
        try:
            os.mkdir(lock)
            break
        except FileExistsError:
            if time.monotonic() > deadline:
                raise SoilVolumeError(
                    f"{lock}: another soilvolume run has held this lock for {wait_s:g} s; remove it if no run is going"
                ) from None
            time.sleep(0.05)
    try:
        yield
    finally:
        os.rmdir(lock)
