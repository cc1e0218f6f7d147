"""An existing output this user may not replace although its folder is writable, refused before
any work."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from .types import SoilVolumeError


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
