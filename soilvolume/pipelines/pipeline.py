"""PDAL pipelines preparing a cloud: built from the engine's options, or users' files, run by the
``pdal`` bindings when they import, else by the embedded executor (:mod:`.stages`)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import SoilVolumeError
from ..inputs.io import GROUND, LAS_SUFFIXES, TEXT_SUFFIXES, RawPoints, atomic_path
from ..inputs.lasheader import check_las_header
from ..inputs.smrf import DEFAULTS as CSF_DEFAULTS
from ..inputs.stream import Source, from_raw
from ..inputs.stream import open_source as open_file
from . import stages as embedded
from .confine import confine_writers
from .load import READERS, load_pipeline
from .stages.view import PointView

#: a reader's SRS options, kept when a user's pipeline reads another file (see :func:`prepare_cloud_from_file`)
SRS_OPTS = ("override_srs", "spatialreference", "default_srs")


def _text_reader(path: Path) -> dict[str, Any]:
    """readers.text for a file; a header is supplied when the first line holds numbers."""
    stage: dict[str, Any] = {"type": "readers.text", "filename": str(path)}
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            first = next((ln for ln in fh if ln.strip()), "")
    except OSError as exc:
        raise SoilVolumeError(f"{path}: cannot read ({exc})") from exc
    sep = "," if "," in first else " "
    fields = [f for f in (first.split(",") if sep == "," else first.split()) if f.strip()]
    try:
        [float(f) for f in fields]
    except ValueError:
        return stage  # the file has its own header line
    if len(fields) < 3:
        raise SoilVolumeError(f"{path}: expected at least x y z columns")
    extra = [f"Column{chr(ord('D') + i)}" for i in range(len(fields) - 3)]
    stage["header"] = sep.join(["X", "Y", "Z", *extra])
    if sep == " ":
        stage["separator"] = " "
    return stage


def reader_stage(path: str | os.PathLike, default_srs: str | None = None) -> dict[str, Any]:
    """The reader for a cloud file (LAS/LAZ, PLY, PCD, XYZ/TXT/CSV/PTS)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in TEXT_SUFFIXES:
        stage = _text_reader(p)
    elif suffix in READERS:
        stage = {"type": READERS[suffix], "filename": str(p)}
    else:
        raise SoilVolumeError(f"{p}: no PDAL reader for '{p.suffix}' files")
    if default_srs:
        stage["default_srs"] = default_srs
    return stage


def has_ground_class(path: str | os.PathLike) -> bool:
    """Whether a LAS/LAZ file has points of class 2 (for ``ground='auto'``)."""
    if Path(path).suffix.lower() not in LAS_SUFFIXES:
        return False
    import laspy

    check_las_header(Path(path))
    with laspy.open(path) as reader:  # every LAS point format has a classification
        return any(np.any(np.asarray(chunk.classification) == GROUND) for chunk in reader.chunk_iterator(2_000_000))


def _ground_stages(ground: str, smrf: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The stages keeping the ground of a mode: class 2, the SMRF (``filter``, options ``smrf``) or
    the cloth simulation (``csf``) filter, or none."""
    keep = {"type": "filters.range", "limits": "Classification[2:2]"}
    if ground == "filter":
        classify = {"type": "filters.smrf", **(smrf or {})}
    elif ground == "csf":
        classify = {"type": "filters.csf", **CSF_DEFAULTS}
    else:
        return [keep] if ground == "class" else []
    return [{"type": "filters.assign", "value": "Classification = 0"}, classify, keep]


def build_prepare_pipeline(
    path: str | os.PathLike,
    *,
    in_srs: str | None = None,
    out_srs: str | None = None,
    polygon: str | None = None,
    ground: str = "none",
    output: str | os.PathLike | None = None,
    smrf: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """The engine's preparation of one cloud as PDAL stages: read (``in_srs`` when the file has no
    CRS), reproject to ``out_srs``, crop to the WKT ``polygon``, keep the ground (:func:`_ground_stages`;
    ``auto``: class when the file has class 2, else none), write the LAS/LAZ ``output``."""
    if ground == "auto":
        ground = "class" if has_ground_class(path) else "none"
    if ground not in ("none", "class", "filter", "csf"):
        raise SoilVolumeError(f"ground '{ground}': use auto, class, filter, csf or none")
    out: list[dict[str, Any]] = [reader_stage(path, in_srs)]
    if out_srs:
        out.append({"type": "filters.reprojection", "out_srs": out_srs})
    if polygon:
        out.append({"type": "filters.crop", "polygon": polygon})
    out += _ground_stages(ground, smrf)
    if output is not None:
        if Path(output).suffix.lower() not in LAS_SUFFIXES:
            raise SoilVolumeError(f"{output}: the prepared cloud is written as .las or .laz")
        out.append({"type": "writers.las", "filename": str(output), **{f"scale_{a}": 0.001 for a in "xyz"}})
    return out


def dumps(stages: list[dict[str, Any]]) -> str:
    """Pipeline JSON as ``pdal pipeline`` reads it."""
    return json.dumps({"pipeline": stages}, indent=2) + "\n"


def save_pipeline(stages: list[dict[str, Any]], path: str | os.PathLike) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(dumps(stages), encoding="utf-8")


def run_pipeline(stages: list[dict[str, Any]], source: str = "<pipeline>") -> PointView:
    """Run stages with real PDAL when its bindings import (its views' points concatenated in PDAL's
    dimension names), else with the embedded executor."""
    try:
        import pdal  # type: ignore[import-not-found]
    except Exception:  # ImportError, or a broken libpdal
        return embedded.execute(stages, source)
    try:
        p = pdal.Pipeline(json.dumps({"pipeline": stages}))
        p.execute()
        arrays = [a for a in p.arrays if len(a)]
    except RuntimeError as exc:
        raise SoilVolumeError(f"pipeline {source}: PDAL failed ({exc})") from exc
    if not arrays:
        return PointView({k: np.empty(0) for k in "XYZ"}, None)
    data = np.concatenate(arrays) if len(arrays) > 1 else arrays[0]
    out = {name: np.asarray(data[name], dtype=np.float64 if name in "XYZ" else None) for name in data.dtype.names}
    return PointView(out, getattr(p, "srswkt2", None) or None)  # the bindings' SRS


def view_to_raw(view: PointView, path: str, source: str = "<pipeline>") -> RawPoints:
    """A pipeline's result as :class:`RawPoints` (in the view's SRS units: the engine converts Z)."""
    if len(view) == 0:
        raise SoilVolumeError(f"pipeline {source}: no points left after the pipeline ({path})")
    cls = view.arrays.get("Classification")
    return RawPoints(view.xyz, None if cls is None else cls.astype(np.uint8), view.srs_wkt, path)


def prepare_cloud_from_file(pipeline: str | os.PathLike, path: str | os.PathLike | None = None) -> RawPoints:
    """A user's preparation pipeline run on ``path`` (default: the pipeline's own reader file): its
    reader's filename replaced (``pdal pipeline --readers.las.filename=...``), the reader's type that
    of the file's format, its SRS options kept."""
    stages = load_pipeline(pipeline)
    if path is not None:
        reader, fresh = dict(stages[0]), reader_stage(path)
        if fresh["type"] != reader["type"]:
            reader = {**fresh, **{k: v for k, v in reader.items() if k in SRS_OPTS}}
        stages = [{**reader, "filename": str(path)}, *stages[1:]]
    stages = confine_writers(stages, str(pipeline))
    view = run_pipeline(stages, str(pipeline))
    return view_to_raw(view, stages[0]["filename"], str(pipeline))


def open_source(path: str | os.PathLike, pipeline: str | os.PathLike | None = None) -> Source:
    """A cloud to stream, or the points ``pipeline`` prepares from ``path``, in memory."""
    if pipeline:
        return from_raw(prepare_cloud_from_file(pipeline, path))
    return open_file(path)
