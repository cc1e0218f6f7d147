"""The stockpile inventory's options and the run control (where and how a run goes, never its numbers)."""

from __future__ import annotations

from .table import ESTIMATE, REGISTER, STOCKPILE, option, options

HELP = {
    "base": "what each pile's volume is measured from: triangulated (a surface through its toe line, the common "
    "practice), plane (a plane fit to the toe), lowest, average or highest (a level at the toe's lowest, mean or "
    "highest height), elevation:Z (a level at Z metres, the survey's heights), surface:DEM (a GeoTIFF such as an "
    "earlier survey's DEM or a design, resampled onto the grid)",
    "density": "bulk density (t/m3) for tonnage, for every pile without its own density field",
    "threads": "worker threads of the registration (its nearest-neighbour searches and Open3D; 0 = all cores)",
    "scheduler": "where the work runs: none (in-process), threads[:N] (tiles on N threads), local[:N] (tiles on a Dask LocalCluster of N worker processes), tcp://HOST[:PORT] (an existing Dask cluster, port 8786 by default; its workers must see the input paths), auto (in-process when the pair fits {opt:memory_limit}, else local)",
    "memory_limit": "memory budget (GB) of the run: auto chooses in-process below it, and a LocalCluster shares it among its workers, at least 0.25 GB each (0 = half of this machine's memory)",
    "tile_cells": "side (cells) of the tiles the distributed engine grids one task at a time (0 = from the point density: what half of a worker's share of {opt:memory_limit} holds, at most 32 million points, at least two tiles per worker, snapped to a VPC's tiles when one fits)",
    "volume_step": "where a distributed run's volume step (holes, correction, change areas, uncertainty) runs: whole (the whole grid in the driver process; results equal the in-process run), tiles (tile by tile on the workers with halos, the correction and stable ground found on an overview of the grid; for grids too large for one process), auto (tiles when the grid exceeds half of {opt:memory_limit})",
    "keep_registered_cloud": "write after_registered.laz (the after cloud moved by the registration; the transform is always in report.json)",
}


@options(HELP)
class ProductOptions:
    """The stockpile inventory's options and the run control (where and how a run goes, never its numbers)."""

    # stockpile inventory
    base: str = option("triangulated", "Stockpile base surface", STOCKPILE)
    density: float | None = option(None, "Bulk density", STOCKPILE, "t/m3", 0.0, 100.0, lo_open=True)
    # run control
    threads: int = option(0, "Threads", REGISTER, None, 0, 1024, run_control=True)
    scheduler: str = option("auto", "Scheduler", run_control=True)
    memory_limit: float = option(0.0, "Memory budget", ESTIMATE, "GB", 0.0, 1e6, run_control=True)
    tile_cells: int = option(0, "Tile size", ESTIMATE, "cells", 0, 100000)
    volume_step: str = option("auto", "Volume step", choices=("auto", "whole", "tiles"))
    keep_registered_cloud: bool = option(False, "Write the registered after cloud", run_control=True)
