"""The single-step commands: one cloud to a DEM (``soilvolume dem``) and registration only
(``soilvolume register``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.hooks import Hooks
from ..core.outputs import check_output_file, os_errors
from ..core.types import SoilVolumeError
from ..dem import grid as gridmod
from ..inputs.footprint import footprint, polygon_area
from ..inputs.io import LAS_SUFFIXES, write_las_chunked
from ..options import Options
from ..registration.register import register
from ..reporting.report import _clean, absolute_transform, stage_dict
from ..validate import check_grid_cells
from ..volumes.compute import centred_heights
from .steps import prepare_pair


def run_cloud_to_dem(cloud: Path, out_tif: Path, options: Options, *, crs, bounds, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.cloud_to_dem`."""
    from ..inputs.prepare import prepare_single
    from ..inputs.stream import open_source

    out_tif = check_output_file(out_tif, [cloud])
    hooks.step(5, f"reading {cloud.name}")
    one = prepare_single(open_source(cloud), crs, options, check=hooks.ticker(5, 40, "reading"))
    xyz, origin, frame = one.xyz, one.origin, one.frame
    if bounds is not None:
        u = frame.xy_unit
        lo = np.array([bounds[0] * u, bounds[1] * u, 0]) - origin
        hi = np.array([bounds[2] * u, bounds[3] * u, 0]) - origin
    else:
        lo, hi = xyz.min(axis=0).astype(float), xyz.max(axis=0).astype(float)
    cell = options.cell or gridmod.choose_cell(len(xyz), polygon_area(footprint(one.thin[:, :2])))
    grid = gridmod.make_grid(lo, hi, cell, origin, frame.wkt, frame.xy_unit)
    check_grid_cells(grid.rows, grid.cols, cell)
    hooks.step(40, f"gridding {len(xyz):,} points on {grid.rows} x {grid.cols} cells of {cell} m")
    h = centred_heights(gridmod.epoch_dem(xyz, grid, options.statistic), cell, options)
    if not np.isfinite(h).any():
        raise SoilVolumeError(f"{cloud}: no points inside the grid (check --bounds)")
    hooks.step(90, f"writing {out_tif.name}")
    with os_errors(out_tif):
        gridmod.write_geotiff(out_tif, h + origin[2], grid, f"average height ({options.statistic}, cell centres) (m)")
    hooks.step(100, "done")
    return {
        "cell_m": cell,
        "rows": grid.rows,
        "cols": grid.cols,
        "crs": frame.crs.name,
        "transform": list(grid.transform)[:6],
        "points": int(len(xyz)),
        "valid_cells": int(np.isfinite(h).sum()),
        "selection": one.note,
    }


def run_register(before: Path, after: Path, out_cloud: Path, options: Options, *, hooks: Hooks) -> dict:
    """See :func:`soilvolume.api.register`."""
    out_cloud = check_output_file(out_cloud, [before, after])
    if out_cloud.suffix.lower() not in LAS_SUFFIXES:
        raise SoilVolumeError(f"{out_cloud}: the registered cloud is written as .las or .laz")
    hooks.step(5, "reading")
    prep = prepare_pair(before, after, options, hooks, None, None)
    hooks.step(20, "registering")
    reg = register(
        prep.after_thin,
        prep.before_thin,
        options,
        check=hooks.ticker(20, 90, "registering"),
        dense=(prep.after.xyz, prep.before.xyz),
    )
    hooks.step(90, "writing the registered cloud")
    with os_errors(out_cloud):
        write_las_chunked(out_cloud, prep.after_chunks(), prep.origin, prep.frame.wkt, reg.transform)
    hooks.step(100, "done")

    return _clean(
        {
            "transform": absolute_transform(reg.transform, prep.origin),
            "coarse": stage_dict(reg.coarse),
            "fine": stage_dict(reg.fine),
        }
    )
