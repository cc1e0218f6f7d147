"""An output folder filled all-or-nothing: files are written into a hidden staging folder inside
it and moved into place only when the whole run succeeded."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from .types import SoilVolumeError


class OutputDir:
    """Staging for one run's outputs; ``commit()`` moves them into ``final``."""

    def __init__(self, final: Path, inputs: list[Path], overwrite: bool) -> None:
        self.final = final.resolve()
        resolved = {p.resolve() for p in inputs}
        if self.final in resolved:
            raise SoilVolumeError(f"{final}: the output folder is one of the input files")
        if self.final.exists() and not self.final.is_dir():
            raise SoilVolumeError(f"{final}: exists and is not a folder")
        if self.final.exists() and any(self.final.iterdir()) and not overwrite:
            raise SoilVolumeError(f"{final}: output folder exists and is not empty (use --overwrite)")
        self.inputs = resolved
        self.created = not self.final.exists()
        self.final.mkdir(parents=True, exist_ok=True)
        self.stage = Path(tempfile.mkdtemp(prefix=".soilvolume-partial-", dir=self.final))

    def path(self, name: str) -> Path:
        if (self.final / name).resolve() in self.inputs:
            raise SoilVolumeError(f"{self.final / name}: refusing to overwrite an input file")
        return self.stage / name

    def commit(self) -> dict[str, Path]:
        """Move every staged file into the final folder; returns name -> final path."""
        moved = {}
        for f in sorted(self.stage.iterdir()):
            os.replace(f, self.final / f.name)
            moved[f.name] = self.final / f.name
        self.stage.rmdir()
        return moved

    def abort(self) -> None:
        shutil.rmtree(self.stage, ignore_errors=True)
        if self.created and not any(self.final.iterdir()):
            self.final.rmdir()
