"""The shortened runs of :mod:`.run`: one cloud to a DEM (``soilvolume dem``: prepare, grid,
write) and registration only (``soilvolume register``: prepare, register, write), in-process."""

from __future__ import annotations

from pathlib import Path

from ..core.hooks import Hooks
from ..core.outputs import check_output_file
from ..core.types import Epoch, SoilVolumeError
from ..core.wording import cli_tree
from ..inputs.distinct import check_two_surveys
from ..inputs.io import LAS_SUFFIXES
from ..options import Options
from ..reporting.report import dem_summary, registration_summary
from .executors import InProcess
from .run import Run, drive


def run_cloud_to_dem(cloud: Path, out_tif: Path, options: Options, *, crs, bounds, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.cloud_to_dem`."""
    out_tif = check_output_file(out_tif, [cloud])
    run = drive(Run("dem", (Epoch(cloud),), options, hooks, raster_out=out_tif, crs=crs, bounds=bounds), InProcess())
    hooks.step(100, "done")
    return cli_tree(dem_summary(run.prep, run.grid, run.dems[0]))


def run_register(before: Path, after: Path, out_cloud: Path, options: Options, *, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.register`."""
    check_two_surveys(before, after)
    out_cloud = check_output_file(out_cloud, [before, after])
    if out_cloud.suffix.lower() not in LAS_SUFFIXES:
        raise SoilVolumeError(f"{out_cloud}: the registered cloud is written as .las or .laz")
    run = drive(Run("register", (Epoch(before), Epoch(after)), options, hooks, cloud_out=out_cloud), InProcess())
    hooks.step(100, "done")
    return cli_tree(registration_summary(run.reg, run.prep.origin))  # options worded as flags
