"""Coarse (:mod:`.coarse`) and fine (:mod:`.fine`) registration of the after cloud onto the before
cloud, local frame; each stage a :class:`~soilvolume.core.types.StageQuality` (transform, fitness, RMSE)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..core.record import Georeferencing
from ..core.types import SoilVolumeError, StageQuality
from ..options import Options
from . import columns
from .coarse import coarse_stage
from .fine import fine_stage
from .ground import EVAL_DISTANCE, evaluate_surface, judged, spacing
from .o3d import limit_threads

AUTO_FITNESS = 0.6  # --coarse auto runs FPFH only when the fine stage from the GPS pose fits worse


@dataclass(frozen=True)
class Registration:
    """The accepted transform (after -> before), each stage's quality, the georeferencing trust."""

    transform: np.ndarray
    coarse: StageQuality
    fine: StageQuality
    georeferencing: Georeferencing | None = None


def register(
    after_xyz: np.ndarray,
    before_xyz: np.ndarray,
    options: Options,
    check: Callable[[], None] | None = None,
    dense: tuple[np.ndarray, np.ndarray] | None = None,
    precise: bool = False,
) -> Registration:
    """Register after onto before (local, thinned; before cropped to the after footprint + radius).
    ``dense``: the full-resolution (after, before) clouds, for the paper's PFH."""
    eye = np.eye(4)
    if precise:
        gap = spacing(before_xyz)
        fit, rmse = evaluate_surface(judged(after_xyz, gap), before_xyz, eye, gap)
        skipped = "skipped: coordinates used as georeferenced ({opt:georeferencing})"
        return Registration(
            eye,
            StageQuality("none", float("nan"), float("nan"), eye, False, 0.0, skipped),
            StageQuality("none", fit, rmse, eye, True, 0.0, skipped),
        )
    limit_threads(options.threads)
    target = columns.Cloud(before_xyz)  # the fine stage's many boxes on the before cloud share its cuts
    if options.coarse == "auto" and options.fine != "none":
        first = fine_stage(after_xyz, target, [(eye, "gps")], options, check, dense)
        if first.fitness >= AUTO_FITNESS:  # the GPS pose converged: FPFH cannot do better here
            note = (
                f"skipped: the fine registration from the GPS pose fits ({first.fitness:.0%} of the "
                f"after cloud within {EVAL_DISTANCE} m); {{opt:coarse=fpfh}} forces it"
            )
            return Registration(
                first.transform, StageQuality("fpfh-ransac", float("nan"), float("nan"), eye, False, 0.0, note), first
            )
    coarse = coarse_stage(after_xyz, before_xyz, options)
    starts = [(eye, "gps")]
    if coarse.accepted and not np.allclose(coarse.transform, eye):
        starts.append((coarse.transform, "coarse"))
    best = fine_stage(after_xyz, target, starts, options, check, dense)
    if options.coarse == "auto" and coarse.accepted and "gps" in best.note:
        note = coarse.note + "; rejected: fine registration fits better from the GPS pose"
        coarse = replace(coarse, accepted=False, note=note)
    if best.fitness < 0.2:
        raise SoilVolumeError(
            f"registration failed: only {best.fitness:.0%} of the after cloud lies within "
            f"{EVAL_DISTANCE} m of the before surface (RMSE {best.rmse:.3f} m); check that both "
            "clouds cover the same site and their CRSs"
        )
    return Registration(best.transform, coarse, best)
