"""The stockpile inventory's options and the run control (where and how a run goes, never its numbers)."""

from __future__ import annotations

from dataclasses import dataclass

from .table import REGISTER, STOCKPILE, option


@dataclass(frozen=True)
class ProductOptions:
    """The stockpile inventory's options and the run control (where and how a run goes, never its numbers)."""

    # stockpile inventory
    base: str = option(
        "triangulated",
        "what each pile's volume is measured from: triangulated (a surface through its toe line, the common "
        "practice), plane (a plane fit to the toe), lowest, average or highest (a level at the toe's lowest, mean or "
        "highest height), elevation:Z (a level at Z metres, the survey's heights), surface:DEM (a GeoTIFF such as an "
        "earlier survey's DEM or a design, resampled onto the grid)",
        label="Stockpile base surface",
        commands=STOCKPILE,
    )
    density: float | None = option(
        None,
        "bulk density (t/m3) for tonnage, for every pile without its own density field",
        label="Bulk density",
        unit="t/m3",
        lo=0.0,
        lo_open=True,
        hi=100.0,
        commands=STOCKPILE,
    )
    # run control
    threads: int = option(
        0,
        "worker threads of the registration (its nearest-neighbour searches and Open3D; 0 = all cores)",
        label="Threads",
        lo=0,
        hi=1024,
        commands=REGISTER,
        run_control=True,
    )
    scheduler: str = option(
        "auto",
        "where the work runs: none (in-process), threads[:N] (tiles on N threads), local[:N] (tiles on a Dask LocalCluster of N worker processes), tcp://HOST[:PORT] (an existing Dask cluster, port 8786 by default; its workers must see the input paths), auto (in-process when the pair fits {opt:memory_limit}, else local)",
        label="Scheduler",
        run_control=True,
    )
    memory_limit: float = option(
        0.0,
        "memory budget (GB) of the run: auto chooses in-process below it, and a LocalCluster shares it among its workers, at least 0.25 GB each (0 = half of this machine's memory)",
        label="Memory budget",
        unit="GB",
        lo=0.0,
        hi=1e6,
        run_control=True,
    )
    tile_cells: int = option(
        0,
        "side (cells) of the tiles the distributed engine grids one task at a time (0 = from the point density: what half of a worker's share of {opt:memory_limit} holds, at most 32 million points, at least two tiles per worker, snapped to a VPC's tiles when one fits)",
        label="Tile size",
        unit="cells",
        lo=0,
        hi=100000,
    )
    volume_step: str = option(
        "auto",
        "where a distributed run's volume step (holes, correction, change areas, uncertainty) runs: whole (the whole grid in the driver process; results equal the in-process run), tiles (tile by tile on the workers with halos, the correction and stable ground found on an overview of the grid; for grids too large for one process), auto (tiles when the grid exceeds half of {opt:memory_limit})",
        ("auto", "whole", "tiles"),
        label="Volume step",
    )
    keep_registered_cloud: bool = option(
        False,
        "write after_registered.laz (the after cloud moved by the registration; the transform is always in report.json)",
        label="Write the registered after cloud",
        run_control=True,
    )
