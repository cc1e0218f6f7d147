"""Two inputs that must be different surveys: one file given twice (the same path, a symbolic or
hard link to it, or a byte-for-byte copy) compares a survey with itself, 0 ± 0 m3, and is refused."""

from __future__ import annotations

import filecmp
import os
from pathlib import Path

from ..core.types import SoilVolumeError


def sameness(a: Path, b: Path) -> str | None:
    """How ``b`` is ``a``: "is the same file as" (a path or link to it), "is a byte-for-byte copy of", or None."""
    try:
        if os.path.samefile(a, b):
            return "is the same file as"
        if a.is_file() and b.is_file() and filecmp.cmp(a, b, shallow=False):
            return "is a byte-for-byte copy of"
    except OSError:  # missing or unreadable: the reading says so
        return None
    return None


def check_two_surveys(before: Path, after: Path, what: str = "the before survey") -> None:
    """Refuse an ``after`` that is ``before`` (see :func:`sameness`), naming both files."""
    how = sameness(Path(before), Path(after))
    if how:
        raise SoilVolumeError(
            f"{after}: {how} {what} {before}; before and after must be two surveys of the site at different times"
        )
