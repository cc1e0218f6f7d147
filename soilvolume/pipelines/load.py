"""Users' pipeline files (or JSON text) loaded and checked: PDAL's shorthand forms normalised to
stages, every option's type checked, errors naming the file and the problem."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from ..core.types import SoilVolumeError

#: PDAL's reader/writer inference from a filename's extension: its format's readers./writers. stage
FORMATS = {".las": "las", ".laz": "las", ".ply": "ply", ".pcd": "pcd", ".txt": "text", ".csv": "text"}
READERS = {suffix: f"readers.{name}" for suffix, name in FORMATS.items()}
WRITERS = {
    suffix: f"writers.{name}" for suffix, name in {**FORMATS, ".tif": "gdal", ".tiff": "gdal", ".vrt": "gdal"}.items()
}
#: largest pipeline file read (a pipeline with a detailed crop polygon is a few MB)
MAX_BYTES = 64 << 20

#: the types of the options of the project's own stages (others are left to PDAL to check)
NUMERIC = {"cell", "window", "slope", "threshold", "scalar", "resolution", "rigidness", "step", "iterations"} | {
    f"scale_{a}" for a in "xyz"
}
BOOLEAN = {"smooth"}
STRING = {"type", "filename", "out_srs", "header", "separator", "default_srs", "override_srs", "spatialreference"}
STRING_OR_LIST = {"limits", "polygon", "value"}


def _check_value(name: str, value: Any, where: str) -> None:
    def bad(expect: str) -> SoilVolumeError:
        return SoilVolumeError(f"{where}: option '{name}' must be {expect}, got {value!r}")

    if value is None:
        raise bad("set (not null)")
    if name in NUMERIC:
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise bad("a number")
        try:
            float(value)
        except ValueError:
            raise bad("a number") from None
    elif name in BOOLEAN:
        if not (isinstance(value, bool) or str(value).lower() in ("true", "false")):
            raise bad("true or false")
    elif name in STRING and not isinstance(value, str):
        raise bad("a string")
    elif name in STRING_OR_LIST:
        items = value if isinstance(value, list) else [value]
        if not items or not all(isinstance(v, (str, dict)) for v in items):
            raise bad("a string or a list of strings")


def normalise(raw: Any, name: str) -> list[dict[str, Any]]:
    """The stages of a parsed pipeline, shorthand forms made stages and options type-checked."""
    if isinstance(raw, dict):
        if "pipeline" not in raw:
            raise SoilVolumeError(f"pipeline {name}: an object needs a 'pipeline' list")
        raw = raw["pipeline"]
    if not isinstance(raw, list):
        raise SoilVolumeError(
            f'pipeline {name}: expected a list of stages or {{"pipeline": [...]}}, got {type(raw).__name__}'
        )
    if not raw:
        raise SoilVolumeError(f"pipeline {name}: the pipeline has no stages (missing reader)")
    out: list[dict[str, Any]] = []
    for i, entry in enumerate(raw):
        where = f"pipeline {name}: stage {i + 1}"
        if not isinstance(entry, (str, dict)):
            raise SoilVolumeError(f"{where} must be an object or a filename string, got {type(entry).__name__}")
        stage = {"filename": entry} if isinstance(entry, str) else dict(entry)
        kind = stage.get("type")
        if kind is None:
            fname = stage.get("filename")
            if not isinstance(fname, str):
                raise SoilVolumeError(f"{where} has no 'type' (and no filename to infer it from)")
            table = READERS if i == 0 else WRITERS if i == len(raw) - 1 else None
            if table is None:
                raise SoilVolumeError(f"{where}: a bare filename must be the first (reader) or the last (writer) stage")
            kind = table.get(Path(fname).suffix.lower())
            if kind is None:
                raise SoilVolumeError(f"{where}: cannot infer a stage for '{fname}'")
            stage = {"type": kind, **stage}
        for key, value in stage.items():
            _check_value(key, value, f"{where} ({kind})")
        out.append(stage)
    first = out[0]
    if not first["type"].startswith("readers."):
        raise SoilVolumeError(
            f"pipeline {name}: missing reader: the first stage is "
            f"'{first['type']}', not a reader (e.g. readers.las) or a filename"
        )
    if not isinstance(first.get("filename"), str) or not first["filename"]:
        raise SoilVolumeError(f"pipeline {name}: the reader {first['type']} has no filename")
    return out


def _read_text(path: Path, name: str) -> str:
    """A pipeline file's text: a regular file of at most :data:`MAX_BYTES`, UTF-8."""
    try:
        if path.exists() and not path.is_dir() and not path.is_file():
            raise SoilVolumeError(f"pipeline {name}: not a regular file (a device or pipe)")
        if path.is_file() and path.stat().st_size > MAX_BYTES:
            raise SoilVolumeError(f"pipeline {name}: larger than {MAX_BYTES >> 20} MB, not a pipeline file")
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SoilVolumeError(f"pipeline {name}: cannot read ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise SoilVolumeError(f"pipeline {name}: not UTF-8 text (byte {exc.start})") from exc


def load_pipeline(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Stages of a pipeline file (``{"pipeline": [...]}`` or a list; strings are a reader's or a
    writer's filename, as PDAL takes them), checked; errors name the file."""
    name = str(path)
    try:
        raw = json.loads(_read_text(Path(path), name))
    except json.JSONDecodeError as exc:
        raise SoilVolumeError(
            f"pipeline {name}: invalid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from exc
    except RecursionError as exc:
        raise SoilVolumeError(f"pipeline {name}: invalid JSON (nested too deeply)") from exc
    return normalise(raw, name)
