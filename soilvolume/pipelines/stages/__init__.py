"""The embedded executor, for machines without PDAL: only the stages and options of the project's
own pipelines (:data:`REGISTRY`); any other is one error saying it needs PDAL, before any stage runs
(no option silently ignored, nothing written)."""

from __future__ import annotations

from collections.abc import Callable

from ...core.types import SoilVolumeError
from ...inputs.smrf import DEFAULTS as CSF_DEFAULTS
from ..load import normalise
from . import files, filters
from .view import PointView, StageContext

StageFn = Callable[[PointView | None, dict, StageContext], PointView]

#: options every stage accepts (PDAL's general stage options that change nothing here)
GENERIC = {"type", "tag", "user_data"}

_FILE = frozenset({"filename", "default_srs"})
#: each stage's function and options (docs/cli.md lists them)
REGISTRY: dict[str, tuple[StageFn, frozenset[str]]] = {
    **{f"readers.{name}": (files.read_file, _FILE) for name in ("las", "ply", "pcd")},
    "readers.text": (files.read_text, _FILE | {"header", "separator"}),
    "filters.reprojection": (filters.reproject, frozenset({"out_srs"})),
    "filters.crop": (filters.crop, frozenset({"polygon"})),
    "filters.assign": (filters.assign, frozenset({"value"})),
    "filters.range": (filters.filter_range, frozenset({"limits"})),
    "filters.smrf": (filters.smrf, frozenset({"cell", "slope", "window", "threshold", "scalar"})),
    "filters.csf": (filters.csf, frozenset(CSF_DEFAULTS)),
    "writers.las": (files.write_las, frozenset({"filename", "scale_x", "scale_y", "scale_z"})),
}


def _checked(stage: dict, source: str) -> StageFn:
    """The function of a stage, or the error naming the stage or option that needs PDAL."""
    kind = stage.get("type")
    if kind not in REGISTRY:
        raise SoilVolumeError(
            f"pipeline {source}: stage '{kind}' needs PDAL (without the pdal Python bindings only the "
            f"stages of soilvolume's own pipelines run: {', '.join(REGISTRY)})"
        )
    fn, allowed = REGISTRY[kind]
    for name in stage:
        if name not in allowed and name not in GENERIC:
            raise SoilVolumeError(
                f"pipeline {source}: option '{name}' of {kind} needs PDAL (without the pdal Python "
                f"bindings {kind} takes only {', '.join(sorted(allowed))})"
            )
    return fn


def execute(stages: list[dict], source: str = "<pipeline>") -> PointView:
    """Run a linear pipeline (one reader first, then filters and writers in order), its stages and
    options checked as a loaded file's (:func:`soilvolume.pipelines.load.normalise`)."""
    stages = normalise(stages, source)
    fns = [_checked(s, source) for s in stages]
    if sum(s["type"].startswith("readers.") for s in stages) > 1:
        raise SoilVolumeError(
            f"pipeline {source}: several readers need PDAL (the embedded executor runs exactly one "
            "reader, as the first stage)"
        )
    view: PointView | None = None
    for stage, fn in zip(stages, fns, strict=True):
        view = fn(view, stage, StageContext(source, stage["type"]))
    return view


__all__ = ["REGISTRY", "PointView", "StageContext", "execute"]
