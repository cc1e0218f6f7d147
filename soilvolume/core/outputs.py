"""All-or-nothing outputs: files are built in a hidden staging folder beside ``--out`` (``.<name>.soilvolume-
staging-<pid>``) and swapped in only when all succeeded (the old set parked as ``.<name>.soilvolume-trash-<pid>``);
a killed run's siblings are removed, or its old set restored, by the next run; an existing output this user
may not replace although its folder is writable is refused before any work."""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from . import interrupt
from .siblings import NAME_MAX, STAGING, TRASH, locked, remove, sibling, sweep, sweep_inside
from .types import SoilVolumeError, short_error

#: what a folder of a previous run may hold for --overwrite to replace it
RUN_SUFFIXES = (".tif", ".tiff", ".json", ".html", ".las", ".laz", ".xml", ".csv")
#: libraries whose write errors (a full disk, a lost mount) arrive as their own exception types
WRITER_LIBRARIES = ("rasterio", "laspy", "lazrs")
#: the files ``estimate`` writes itself (pipeline writers may not take these names)
RUN_OUTPUTS = (
    "dem_before.tif",
    "dem_after.tif",
    "difference.tif",
    "plane_offset.tif",
    "filled_mask.tif",
    "excluded.tif",
    "report.json",
    "report.html",
    "change_areas.geojson",
    "change_areas.gpkg",
    "zones.gpkg",
    "zones.csv",
    "sections.csv",
    "contours.gpkg",
    "grade.tif",
    "after_registered.laz",
)
#: the folders ``estimate`` writes itself (one picture per cross-section line)
RUN_FOLDERS = ("sections",)


def os_problem(exc: OSError, path: str | os.PathLike | None = None) -> SoilVolumeError:
    """An OSError as one line naming the path and the problem."""
    where = path if path is not None else exc.filename
    text = exc.strerror or str(exc).splitlines()[0]
    return SoilVolumeError(f"{where}: {text}" if where else text)


@contextmanager
def os_errors(path: Path | None = None) -> Iterator[None]:
    """OSErrors and the writer libraries' errors of the block as one line naming ``path`` or the error's file:
    the clearest account of a failed write (the OS error, a full disk, or GDAL's first cause)."""
    try:
        yield
    except Exception as exc:
        if not (isinstance(exc, OSError) or type(exc).__module__.startswith(WRITER_LIBRARIES)):
            raise
        if isinstance(exc, OSError) and exc.errno:
            where = exc.filename
            if where and STAGING in str(where):  # a staged file: named where it was going, else the output
                inner = STAGING in Path(where).parent.name and STAGING not in Path(where).name
                where = path / Path(where).name if inner and path is not None else path
            raise os_problem(exc, where or path) from exc
        folder = path if path is not None and path.is_dir() else (path.parent if path is not None else Path.cwd())
        try:
            full = shutil.disk_usage(folder).free < 1 << 20
        except OSError:
            full = False
        cause = exc
        while cause.__cause__ is not None or cause.__context__ is not None:
            cause = cause.__cause__ or cause.__context__
        said = f"cannot write ({'no space left on the device' if full else short_error(cause)})"
        raise SoilVolumeError(f"{path}: {said}" if path is not None else said) from exc


class OutputDir:
    """Staging for one run's output folder: ``commit()`` swaps it in, ``abort()`` removes it; ``inputs`` never
    lie inside it; ``allowed``: what ``--overwrite`` may replace (default: files a run writes)."""

    def __init__(
        self, final: Path, inputs: Iterable[Path | str | None], overwrite: bool, allowed: Iterable[str] | None = None
    ) -> None:
        self.final = Path(os.path.abspath(final))
        if self.final.is_symlink() or self.final.exists():
            self.final = self.final.resolve()
        self.inputs = {Path(p).resolve() for p in inputs if p}
        self.moved: dict[str, Path] = {}  # name -> final path, once committed
        self.overwrite, self.allowed = overwrite, set(allowed) if allowed is not None else None
        sweep_inside(self.final)
        self._check()
        parent = self.final.parent  # made with its missing parents: those created, deepest last
        self.created = [p for p in [parent, *parent.parents] if not p.exists()][::-1]
        for p in self.created:
            try:
                p.mkdir()
            except FileExistsError:
                if not p.is_dir():
                    raise SoilVolumeError(f"{p}: exists and is not a folder") from None
            except OSError as exc:
                raise os_problem(exc, p) from exc
        if not parent.is_dir():
            raise SoilVolumeError(f"{parent}: not a folder")
        self.token = secrets.token_hex(4)
        with locked(self.final.parent):
            sweep(self.final)
            self.inside = os.path.ismount(self.final)  # a mount point cannot be swapped
            self.stage = self._inner() if self.inside else sibling(self.final, STAGING, token=self.token)
            try:
                self.stage.mkdir()
            except OSError as exc:  # parent not writable: an existing, empty, writable folder stages inside itself
                f = self.final
                if not (f.is_dir() and not any(f.iterdir()) and os.access(f, os.W_OK | os.X_OK)):
                    self._drop_parents()
                    raise os_problem(exc, self.final.parent) from exc
                self.inside, self.stage = True, self._inner()
                self.stage.mkdir()

    def _inner(self) -> Path:
        return self.final / f".{STAGING}-{os.getpid()}-{self.token}"

    def _check(self) -> None:
        final = self.final
        for p in self.inputs:
            if p.is_relative_to(final):
                raise SoilVolumeError(f"{final}: the output folder is or contains the input {p}")
        if final.exists() and not final.is_dir():
            raise SoilVolumeError(f"{final}: exists and is not a folder")
        try:
            entries = sorted(final.iterdir()) if final.is_dir() else []
        except OSError as exc:
            raise os_problem(exc, final) from exc
        if final.is_dir() and not os.access(final, os.W_OK | os.X_OK):
            raise SoilVolumeError(f"{final}: the output folder is not writable")
        check_replaceable(final)
        if entries and not self.overwrite:
            raise SoilVolumeError(f"{final}: output folder exists and is not empty (use --overwrite)")
        foreign = [e for e in entries if not self._ours(e)]
        if foreign:
            raise SoilVolumeError(
                f"{final}: --overwrite replaces the whole folder, and it holds "
                f"'{foreign[0].name}' that soilvolume does not write; choose another folder"
            )

    def _ours(self, entry: Path) -> bool:
        if self.allowed is not None:
            return entry.name in self.allowed
        return (
            entry.name.startswith(".soilvolume-partial-")  # earlier versions' staging
            or (entry.is_file() and (entry.name in RUN_OUTPUTS or entry.name.lower().endswith(RUN_SUFFIXES)))
            or (entry.is_dir() and entry.name in RUN_FOLDERS)
        )

    def path(self, name: str) -> Path:
        """Where to write the output ``name`` (inside the staging folder)."""
        if Path(name).name != name or name in ("", ".", ".."):
            raise SoilVolumeError(f"{name}: an output name must be a plain file name")
        return self.stage / name

    def commit(self) -> dict[str, Path]:
        """Swap the staging folder into place; returns name -> final path of every output."""
        interrupt.check()
        names = sorted(p.name for p in self.stage.iterdir())
        if self.inside:  # a mount point or an unswappable folder: file by file, then the stale ones
            for n in names:
                os.replace(self.stage / n, self.final / n)
            self.stage.rmdir()
            for old in self.final.iterdir():
                if old.name not in names and not old.name.startswith(f".{STAGING}-"):
                    remove(old)
        else:
            with locked(self.final.parent), interrupt.cleanup_on_exit(self._restore):
                self._swap()
        return {n: self.final / n for n in names}

    def _swap(self) -> None:
        try:
            os.rename(self.stage, self.final)  # atomic when final is missing or an empty folder (POSIX)
            return
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise os_problem(exc, self.final) from exc
        try:
            self.final.rmdir()  # Windows renames nothing onto a folder, even an empty one: removed while empty
        except OSError:
            pass
        else:
            os.rename(self.stage, self.final)
            return
        if not self.overwrite:
            raise SoilVolumeError(f"{self.final}: another run filled the output folder meanwhile")
        trash = sibling(self.final, TRASH, token=self.token)
        os.rename(self.final, trash)
        os.rename(self.stage, self.final)
        shutil.rmtree(trash, ignore_errors=True)

    def _restore(self) -> None:
        trash = sibling(self.final, TRASH, token=self.token)
        if trash.exists() and not self.final.exists():
            os.rename(trash, self.final)

    def abort(self) -> None:
        """Remove everything this run created."""
        shutil.rmtree(self.stage, ignore_errors=True)
        self._drop_parents()

    def _drop_parents(self) -> None:
        for p in reversed(self.created):
            try:
                p.rmdir()
            except OSError:
                break


@contextmanager
def output_dir(
    final: Path, inputs: Iterable[Path | str | None], overwrite: bool, allowed: Iterable[str] | None = None
) -> Iterator[OutputDir]:
    """An :class:`OutputDir` committed when the block succeeds, removed when it fails."""
    out = OutputDir(final, inputs, overwrite, allowed)
    with interrupt.cleanup_on_exit(out.abort):
        try:
            yield out
            out.moved = out.commit()
        except BaseException:
            out.abort()
            raise


def check_replaceable(final: Path) -> None:
    """Refuse ``final`` when another user's in a sticky folder (/tmp), before the run's last rename would."""
    try:
        st, folder = final.lstat(), final.parent.stat()
    except OSError:
        return
    uid = os.geteuid() if hasattr(os, "geteuid") else 0
    if folder.st_mode & stat.S_ISVTX and uid not in (0, st.st_uid, folder.st_uid):
        raise SoilVolumeError(
            f"{final}: belongs to another user in a folder where only owners may replace files; choose another output"
        )


def check_input_file(path: Path) -> None:
    """Refuse an input that is missing or not a regular file (a FIFO would block GDAL for ever)."""
    if not path.exists():
        raise SoilVolumeError(f"{path}: file not found")
    if not path.is_file():
        raise SoilVolumeError(f"{path}: not a regular file")


def check_output_file(path: Path, inputs: Iterable[Path | str | None]) -> Path:
    """A single output file's absolute path, checked (not an input, its folder writable); killed runs'
    staging files beside it removed."""
    final = Path(os.path.abspath(path))
    if final.exists():
        final = final.resolve()
    if final in {Path(p).resolve() for p in inputs if p}:
        raise SoilVolumeError(f"{path}: refusing to overwrite an input file")
    if final.is_dir():
        raise SoilVolumeError(f"{path}: is a folder, not a file name")
    if final.exists() and not final.is_file():
        raise SoilVolumeError(f"{path}: exists and is not a regular file (a device or pipe is never replaced)")
    if not final.parent.is_dir():
        raise SoilVolumeError(f"{final.parent}: the output folder does not exist")
    if not os.access(final.parent, os.W_OK | os.X_OK):
        raise SoilVolumeError(f"{final.parent}: the output folder is not writable")
    check_replaceable(final)
    if len(final.name.encode()) > NAME_MAX:
        raise SoilVolumeError(f"{path}: file name longer than {NAME_MAX} bytes")
    with locked(final.parent):
        sweep(final)
    return final
