"""PDAL pipelines for preparing a cloud: build them from the engine's options, load users' files,
and run them with the ``pdal`` Python bindings when they import, else with the embedded executor
(:mod:`soilvolume.pipelines.stages`), which implements the same stages with PDAL's documented semantics.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..core.types import SoilVolumeError
from ..inputs.io import GROUND, LAS_SUFFIXES, RawPoints, atomic_path
from . import stages as embedded
from .confine import confine_writers
from .load import READERS, TEXT_SUFFIXES, load_pipeline
from .stages.geometry import format_bounds
from .stages.readers import SRS_OPTS
from .stages.view import PointView

__all__ = [
    "PointView",
    "build_prepare_pipeline",
    "build_dem_stage",
    "dumps",
    "load_pipeline",
    "prepare_cloud",
    "prepare_cloud_from_file",
    "run_pipeline",
    "run_pipeline_file",
    "save_pipeline",
    "view_to_raw",
    "with_input",
]


# ---------------------------------------------------------------------------- building
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

    from ..inputs.lasheader import check_las_header

    check_las_header(Path(path))
    with laspy.open(path) as reader:
        if "classification" not in reader.header.point_format.dimension_names:
            return False
        for chunk in reader.chunk_iterator(2_000_000):
            if np.any(np.asarray(chunk.classification) == GROUND):
                return True
    return False


def _crop_stage(crop: dict[str, Any]) -> dict[str, Any]:
    stage: dict[str, Any] = {"type": "filters.crop"}
    if "polygon" in crop:
        stage["polygon"] = crop["polygon"]
    elif "bounds" in crop:
        stage["bounds"] = format_bounds(*(float(v) for v in crop["bounds"]))
    elif "point" in crop and "distance" in crop:
        stage["point"] = "POINT(" + " ".join(repr(float(v)) for v in crop["point"]) + ")"
        stage["distance"] = float(crop["distance"])
    else:
        raise SoilVolumeError(f"crop {crop!r}: give 'polygon', 'bounds' or 'point' + 'distance'")
    for key in ("outside", "a_srs"):
        if key in crop:
            stage[key] = crop[key]
    return stage


def build_prepare_pipeline(
    path: str | os.PathLike,
    *,
    in_srs: str | None = None,
    out_srs: str | None = None,
    crop: dict[str, Any] | None = None,
    outlier: tuple[int, float] | None = (8, 2.5),
    ground: str = "none",
    z_range: tuple[float | None, float | None] | None = None,
    voxel: float | None = None,
    output: str | os.PathLike | None = None,
    smrf: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """The preparation of one cloud as PDAL stages.

    read (``in_srs`` = the CRS when the file has none) -> reproject to ``out_srs`` -> crop
    (``{"polygon": wkt}``, ``{"bounds": (xmin, ymin, xmax, ymax)}`` or ``{"point": (x, y),
    "distance": r}``, in ``out_srs`` units) -> ground class (``ground='class'``) -> statistical
    outliers ``(mean_k, multiplier)`` removed -> SMRF ground filter (``ground='filter'``, options
    ``smrf``) or the cloth simulation filter (``ground='csf'``, tuned for earthworks) -> Z range ->
    voxel thinning -> optional LAS/LAZ ``output``. ``ground='auto'`` is
    'class' when the file has class-2 points, else 'none'.
    """
    if ground == "auto":
        ground = "class" if has_ground_class(path) else "none"
    if ground not in ("none", "class", "filter", "csf"):
        raise SoilVolumeError(f"ground '{ground}': use auto, class, filter, csf or none")
    out: list[dict[str, Any]] = [reader_stage(path, in_srs)]
    if out_srs:
        out.append({"type": "filters.reprojection", "out_srs": out_srs})
    if crop:
        out.append(_crop_stage(crop))
    if ground == "class":
        out.append({"type": "filters.range", "limits": "Classification[2:2]"})
    if ground in ("filter", "csf"):
        out.append({"type": "filters.assign", "value": "Classification = 0"})
    if outlier is not None:
        k, mult = outlier
        out.append({"type": "filters.outlier", "method": "statistical", "mean_k": int(k), "multiplier": float(mult)})
        out.append({"type": "filters.range", "limits": "Classification![7:7]"})
    if ground in ("filter", "csf"):
        if ground == "filter":
            out.append({"type": "filters.smrf", **(smrf or {})})
        else:
            from .stages.csf import DEFAULTS

            out.append({"type": "filters.csf", **DEFAULTS})
        out.append({"type": "filters.range", "limits": "Classification[2:2]"})
    if z_range is not None:
        lo, hi = ("" if v is None else repr(float(v)) for v in z_range)
        out.append({"type": "filters.range", "limits": f"Z[{lo}:{hi}]"})
    if voxel:
        out.append({"type": "filters.voxelcenternearestneighbor", "cell": float(voxel)})
    if output is not None:
        if Path(output).suffix.lower() not in LAS_SUFFIXES:
            raise SoilVolumeError(f"{output}: the prepared cloud is written as .las or .laz")
        out.append(
            {"type": "writers.las", "filename": str(output), "scale_x": 0.001, "scale_y": 0.001, "scale_z": 0.001}
        )
    return out


def build_dem_stage(
    filename: str | os.PathLike,
    resolution: float,
    *,
    origin: tuple[float, float] | None = None,
    size: tuple[int, int] | None = None,
    output_type: str = "mean",
    nodata: float = -9999.0,
) -> dict[str, Any]:
    """writers.gdal for an average-height DEM: plain binning (``binmode``), origin = lower-left
    corner, ``size`` = (width, height) cells."""
    stage: dict[str, Any] = {
        "type": "writers.gdal",
        "filename": str(filename),
        "resolution": float(resolution),
        "binmode": True,
        "output_type": output_type,
        "data_type": "float64",
        "nodata": nodata,
        "gdaldriver": "GTiff",
    }
    if origin is not None and size is not None:
        stage.update(origin_x=float(origin[0]), origin_y=float(origin[1]), width=int(size[0]), height=int(size[1]))
    return stage


def dumps(stages: list[dict[str, Any]]) -> str:
    """Pipeline JSON as ``pdal pipeline`` reads it."""
    return json.dumps({"pipeline": stages}, indent=2) + "\n"


def save_pipeline(stages: list[dict[str, Any]], path: str | os.PathLike) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(dumps(stages), encoding="utf-8")


# ---------------------------------------------------------------------------- running
def _pdal_module():
    try:
        import pdal  # type: ignore[import-not-found]
    except Exception:  # ImportError, or a broken libpdal
        return None
    return pdal


def _run_pdal(pdal, stages: list[dict[str, Any]], source: str) -> PointView:
    try:
        p = pdal.Pipeline(json.dumps({"pipeline": stages}))
        p.execute()
        arrays = [a for a in p.arrays if len(a)]
    except RuntimeError as exc:
        raise SoilVolumeError(f"pipeline {source}: PDAL failed ({exc})") from exc
    if not arrays:
        return PointView({k: np.empty(0) for k in "XYZ"}, None)
    data = np.concatenate(arrays) if len(arrays) > 1 else arrays[0]
    out: dict[str, np.ndarray] = {}
    for name in data.dtype.names:
        out[name] = np.asarray(data[name], dtype=np.float64 if name in "XYZ" else None)
    if "Classification" in out:
        out["Classification"] = out["Classification"].astype(np.uint8)
    srs = getattr(p, "srswkt2", None)
    if not srs:  # older bindings: the SRS is in the metadata of the last stage
        try:
            meta = p.metadata
            meta = json.loads(meta) if isinstance(meta, str) else meta
            for node in reversed(list(meta["metadata"].values())):
                node = node[0] if isinstance(node, list) else node
                srs = node.get("srs", {}).get("wkt") or node.get("comp_spatialreference")
                if srs:
                    break
        except Exception:
            srs = None
    return PointView(out, srs or None)


def run_pipeline(stages: list[dict[str, Any]], *, engine: str = "auto", source: str = "<pipeline>") -> PointView:
    """Run stages with real PDAL (``engine='pdal'``), the embedded executor ('embedded'), or
    PDAL when ``import pdal`` works else embedded ('auto')."""
    if engine not in ("auto", "pdal", "embedded"):
        raise SoilVolumeError(f"engine '{engine}': use auto, pdal or embedded")
    pdal = None if engine == "embedded" else _pdal_module()
    if engine == "pdal" and pdal is None:
        raise SoilVolumeError(
            "engine 'pdal' requested but the pdal Python bindings do not import "
            "(install PDAL from conda-forge or OSGeo4W)"
        )
    if pdal is not None:
        return _run_pdal(pdal, stages, source)
    return embedded.execute(stages, source)


def view_to_raw(view: PointView, path: str, source: str = "<pipeline>") -> RawPoints:
    """A pipeline's result as the engine's :class:`RawPoints` (coordinates in the view's SRS
    units; the engine converts Z to metres itself)."""
    if len(view) == 0:
        raise SoilVolumeError(f"pipeline {source}: no points left after the pipeline ({path})")
    cls = view.arrays.get("Classification")
    return RawPoints(view.xyz, None if cls is None else cls.astype(np.uint8), view.srs_wkt, path)


def prepare_cloud(path: str | os.PathLike, *, engine: str = "auto", **options: Any) -> RawPoints:
    """Build the preparation pipeline of one cloud (see :func:`build_prepare_pipeline`), run it,
    and return the points."""
    stages = build_prepare_pipeline(path, **options)
    return view_to_raw(run_pipeline(stages, engine=engine, source=str(path)), str(path), str(path))


def run_pipeline_file(pipeline: str | os.PathLike, *, engine: str = "auto") -> RawPoints:
    """A user's preparation pipeline file, run; the points keep the reader's filename as path."""
    stages = confine_writers(load_pipeline(pipeline), str(pipeline))
    view = run_pipeline(stages, engine=engine, source=str(pipeline))
    return view_to_raw(view, stages[0]["filename"], str(pipeline))


def with_input(stages: list[dict[str, Any]], path: str | os.PathLike) -> list[dict[str, Any]]:
    """The stages reading ``path`` instead of the reader's filename (like ``pdal pipeline
    --readers.las.filename=...``); the reader changes type when the file's format needs it, keeping
    its SRS options."""
    reader = dict(stages[0])
    fresh = reader_stage(path)
    if fresh["type"] != reader["type"]:
        reader = {**fresh, **{k: v for k, v in reader.items() if k in SRS_OPTS}}
    reader["filename"] = str(path)
    return [reader, *stages[1:]]


def prepare_cloud_from_file(
    pipeline: str | os.PathLike, path: str | os.PathLike | None = None, *, engine: str = "auto"
) -> RawPoints:
    """A user's preparation pipeline run on ``path`` (default: the pipeline's own reader file)."""
    stages = load_pipeline(pipeline)
    if path is not None:
        stages = with_input(stages, path)
    stages = confine_writers(stages, str(pipeline))
    view = run_pipeline(stages, engine=engine, source=str(pipeline))
    return view_to_raw(view, stages[0]["filename"], str(pipeline))
