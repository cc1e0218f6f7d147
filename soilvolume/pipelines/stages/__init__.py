"""The embedded executor: the stages of the project's own pipelines (those ``soilvolume pipeline
--emit`` writes) re-implemented with numpy/scipy, for machines without PDAL.

Only the stages and options in :data:`REGISTRY` run; any other stage or option is one error naming
it and saying it needs PDAL, raised before any stage runs, so a pipeline never runs with an option
silently ignored and writes nothing when refused.
"""

from __future__ import annotations

from collections.abc import Callable

from ...core.types import SoilVolumeError
from ..load import normalise
from . import crop, ground, readers, reprojection, writers
from . import range as range_stage
from .view import PointView, StageContext

StageFn = Callable[[PointView | None, dict, StageContext], PointView]

#: options every stage accepts (PDAL's general stage options that change nothing here)
GENERIC = {"type", "tag", "user_data"}

REGISTRY: dict[str, tuple[StageFn, frozenset[str]]] = {
    "readers.las": (readers.read_file, frozenset(readers.FILE_OPTS)),
    "readers.ply": (readers.read_file, frozenset(readers.FILE_OPTS)),
    "readers.pcd": (readers.read_file, frozenset(readers.FILE_OPTS)),
    "readers.text": (readers.read_text, frozenset(readers.TEXT_OPTS)),
    "filters.reprojection": (reprojection.reproject, frozenset(reprojection.OPTS)),
    "filters.crop": (crop.crop, frozenset(crop.OPTS)),
    "filters.assign": (range_stage.assign, frozenset(range_stage.ASSIGN_OPTS)),
    "filters.range": (range_stage.filter_range, frozenset(range_stage.RANGE_OPTS)),
    "filters.smrf": (ground.smrf, frozenset(ground.SMRF_OPTS)),
    "filters.csf": (ground.csf, frozenset(ground.CSF_OPTS)),
    "writers.las": (writers.write_las, frozenset(writers.LAS_OPTS)),
}


def check_stage(stage: dict, source: str) -> tuple[StageFn, str]:
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
    return fn, kind


def execute(stages: list[dict], source: str = "<pipeline>") -> PointView:
    """Run a linear pipeline (one reader first, then filters and writers in order), its stages and
    options checked as a loaded file's (:func:`soilvolume.pipelines.load.normalise`)."""
    stages = normalise(stages, source)
    checked = [check_stage(s, source) for s in stages]
    if [kind.startswith("readers.") for _, kind in checked].count(True) > 1:
        raise SoilVolumeError(
            f"pipeline {source}: several readers need PDAL (the embedded executor runs exactly one "
            "reader, as the first stage)"
        )
    view: PointView | None = None
    for stage, (fn, kind) in zip(stages, checked, strict=True):
        view = fn(view, stage, StageContext(source, kind))
    return view


__all__ = ["REGISTRY", "PointView", "StageContext", "check_stage", "execute"]
