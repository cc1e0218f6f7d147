"""The short products, in memory: one cloud to a DEM (``soilvolume dem``) and registration only (``register``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import check_output_file, os_errors
from ..core.types import SoilVolumeError, survey
from ..core.wording import cli_tree
from ..dem.geotiff import write_grid
from ..dem.grid import epoch_dem
from ..execution.inmemory import InMemory
from ..inputs.io import LAS_SUFFIXES, check_two_surveys
from ..options import Options
from ..reporting.report import dem_summary, registration_summary
from ..validate import check_bounds
from ..volumes.compute import centred_heights
from . import steps
from .context import Context, threads
from .plan import cloud_cell, plan_grid


def run_cloud_to_dem(
    cloud: str | Path,
    out_tif: str | Path,
    options: Options | None = None,
    *,
    crs: str | None = None,
    bounds: tuple[float, float, float, float] | None = None,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """One cloud to an average-height GeoTIFF (``api.cloud_to_dem``; ``bounds``: xmin, ymin, xmax, ymax in its
    CRS, snapped outwards to the cell); returns the grid (cell_m, rows, cols, crs, transform, points, valid_cells)."""
    options, bounds, hooks = options or Options(), check_bounds(bounds), hooks or Hooks()
    cloud, out_tif = Path(cloud), check_output_file(Path(out_tif), [cloud])
    ctx = Context((survey(cloud, crs=crs),), options, hooks, ("prepare", "grid", "write"))
    with steps.running(ctx, "prepare", ctx.message("prepare") + InMemory.reading_note, "crop"):
        one = steps.read_one(ctx)
    with steps.running(ctx, "grid", ctx.message("grid"), "grids"):  # on --bounds, else the points' box
        xyz, origin, box = one.xyz, one.origin, one.xyz
        if bounds is not None:  # in CRS units
            b = np.asarray(bounds, dtype=np.float64) * one.frame.xy_unit
            box = (b[:2] - origin[:2], b[2:] - origin[:2])
        cell = cloud_cell(xyz, one.thin, options)
        grid = plan_grid(cell, [box], origin, one.frame, f"{cloud}: --bounds do not make a grid")
        ctx.hooks.step(
            ctx.at("grid", 0.1), f"gridding {len(xyz):,} points on {grid.rows} x {grid.cols} cells of {cell} m"
        )
        heights = centred_heights(epoch_dem(xyz, grid, options.statistic), cell, options)  # at the cell centres
        if not np.isfinite(heights).any():
            raise SoilVolumeError(f"{cloud}: no points inside the grid (check --bounds)")
    with steps.running(ctx, "write", ctx.message("write")), os_errors(out_tif):
        desc = f"average height ({options.statistic}, cell centres) (m)"
        write_grid(out_tif, heights + one.origin[2], grid, desc)
    hooks.step(100, "done")
    return cli_tree(dem_summary(one, grid, heights))


def run_register(
    before: str | Path,
    after: str | Path,
    out_cloud: str | Path,
    options: Options | None = None,
    *,
    hooks: Hooks | None = None,
) -> dict[str, Any]:
    """The after cloud registered onto the before and written (``api.register``; LAS/LAZ, before CRS); returns
    {"transform": 4x4 row-major (after in before CRS -> before), "coarse": {...}, "fine": {...}}."""
    options, hooks, before, after = options or Options(), hooks or Hooks(), Path(before), Path(after)
    check_two_surveys(before, after)
    out_cloud = check_output_file(Path(out_cloud), [before, after])
    if out_cloud.suffix.lower() not in LAS_SUFFIXES:
        raise SoilVolumeError(f"{out_cloud}: the registered cloud is written as .las or .laz")
    threads(options)
    given = ((before, options.before_crs), (after, options.after_crs))
    epochs = tuple(survey(path, crs=crs, georeferencing=options.georeferencing) for path, crs in given)
    ctx, backend = Context(epochs, options, hooks, ("prepare", "register", "write")), InMemory()
    with backend.session(ctx):  # read, register and write the after cloud moved onto the before one
        prep = steps.read(ctx, backend)
        reg, _ = steps.register(ctx, prep, backend.dense(prep))
        backend.keep_cloud(prep, reg, out_cloud)
        steps.write(ctx, backend, None, None, [])
    hooks.step(100, "done")
    return cli_tree(registration_summary(reg, prep.origin))  # options worded as flags
