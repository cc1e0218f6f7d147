"""Every knob of the pipeline in one frozen dataclass, :class:`Options`, each declared once (:func:`option`):
the CLI's flags and the QGIS algorithms' parameters are made from it, so all front ends share its defaults."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import Field, dataclass, field, fields, replace
from typing import Any

__all__ = ["COMMANDS", "Options", "command_fields", "option"]

#: which commands take an option (``commands`` of each field below): the command line builds
#: each subcommand's flags from it and the QGIS algorithms their parameters
ESTIMATE = ("estimate",)  # the commands that take an option unless it says otherwise
VOLUME = ("estimate", "series")  # the volume step (a series runs it once per later epoch)
REGISTER = ("estimate", "register", "series")
PREPARE = ("estimate", "register", "pipeline", "series")  # reading both clouds
GRID = ("estimate", "dem", "series", "stockpile")
GROUND = ("estimate", "register", "dem", "pipeline", "series", "stockpile")  # the ground and its filters
POINTS = ("estimate", "register", "dem", "series", "stockpile")  # what is read of each cloud (the soil rule)
CELLS = ("estimate", "dem", "series")  # the heights of each cell
DESIGNED = ("estimate", "series")  # against a design (a series: --design)
STOCKPILE = ("stockpile",)  # one survey's stockpile inventory
COMMANDS = ("estimate", "register", "dem", "pipeline", "series", "stockpile")


def option(
    default: Any,
    label: str,
    commands: tuple[str, ...] = ESTIMATE,
    unit: str | None = None,
    lo: float | None = None,
    hi: float | None = None,
    *,
    choices: tuple | None = None,
    lo_open: bool = False,
    run_control: bool = False,
    help: str | None = None,
) -> Any:
    """An option: default, GUI ``label``, the ``commands`` taking it, ``unit``, range ``lo``..``hi`` (``lo`` excluded
    when ``lo_open``), ``choices``, ``help`` (or from :func:`options`) and ``run_control``: where and how the run
    goes, never its numbers (every other option keys the work a resumed run may reuse)."""
    meta = {"help": help, "choices": choices, "label": label, "unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open}
    return field(default=default, metadata={**meta, "commands": commands, "run_control": run_control})


def options(helps: dict[str, str]) -> Callable[[type], type]:
    """A frozen dataclass of :func:`option` fields, each with its help from ``helps`` (by name; one each)."""

    def make(cls: type) -> type:
        if helps.keys() != cls.__annotations__.keys():
            raise TypeError(f"{cls.__name__}: the help texts do not match the fields")
        for name, text in helps.items():
            f = getattr(cls, name)
            setattr(cls, name, field(default=f.default, metadata={**f.metadata, "help": text}))
        return dataclass(frozen=True)(cls)

    return make


#: each option's help, by topic in table order
HELP = {
    # inputs: CRS overrides, pipelines, what is read of each cloud
    "before_crs": "CRS of the before cloud when its header has none (e.g. EPSG:32654 or EPSG:2991+6360)",
    "after_crs": "CRS of the after cloud when its header has none",
    # steps 1-4: alignment initialisation, coarse and fine registration, the plane-offset correction
    "radius": "crop radius (m) around the after cloud's footprint applied to the before cloud (paper: 30 m)",
    "coarse": "coarse registration: auto (FPFH+RANSAC only when the fine stage from the GPS pose fits poorly, kept only within the GPS error prior and if it then fits better), fpfh (always, the paper's path), none",
    "coarse_voxel": "voxel size (m) for FPFH features and RANSAC",
    "georeferencing": "how far the surveys' georeferencing is trusted: auto (gps, unless both files declare the same vertical datum and the registration confirms their coordinates: its pose within its own resolution of them, then precise; a declared datum alone proves nothing), gps (GPS-tagged UAV surveys: registered within the prior below), precise (LiDAR, RTK/PPK or ground control: coordinates used as they are, no registration and no bias correction)",
    "max_gps_shift": "georeferencing prior: largest shift (m) registration may apply",
    "max_gps_rotation": "georeferencing prior: largest rotation (degrees, mostly yaw) registration may apply",
    "max_gps_tilt": "georeferencing prior: largest tilt (degrees, about a horizontal axis) registration may apply; a tilt the stable ground cannot pin down stays at 0",
    "fine": "fine registration: icp (robust point-to-plane, coarse-to-fine, change areas down-weighted), gicp, pfh (the paper's PFH + SAC-IA on a patch), none",
    "pfh_patch": "side (m) of the square patch used by {opt:fine=pfh} (paper: 6 m)",
    "seed": "random seed for every RANSAC/sampling step (results are deterministic)",
    "correction": "vertical bias correction: surface (degree-2 polynomial on stable ground), plane (plane on stable ground), paper-plane (the paper's two RANSAC planes, d_i), none",
    "plane_threshold": "RANSAC plane inlier distance (m)",
    "stable_mask": "optional polygon file (GeoPackage/Shapefile/GeoJSON) of ground known to be stable",
    # step 5: grids, heights, holes, change areas, volumes and their uncertainty
    "cell": "grid cell size (m); default from the before cloud's density (>= 8 points per cell, >= 0.5 m)",
    "statistic": "per-cell height: robust-mean (mean after rejecting points beyond 3 MAD of the cell median), mean (the paper), median",
    "min_count_ratio": "a cell of one epoch with fewer points than this fraction of its median count (and always one with fewer than 3) is unreliable: its height is re-filled from neighbours (0 = off)",
    "fill_holes": "fill enclosed holes (cells empty in either epoch, e.g. occlusions) up to this area (m2) by interpolating the height difference around them; larger holes stay empty and are reported (0 = off)",
    "fill_method": "interpolation of refilled cells: biharmonic (smooth, keeps slopes across the hole), harmonic (Laplace, never overshoots its border values)",
    "ground": "ground points: auto (class 2 when the file has ground-classified points, judged on its first million points; else all), class (class 2 only), filter (SMRF ground filter), csf (cloth simulation filter, tuned for earthworks: a 0.5 m cloth of medium stiffness that follows piles and pits and bridges vehicles and bushes; needs the cloth-simulation-filter package), none",
    "ground_window": "{opt:ground=filter}: largest object (m) the SMRF filter removes (vehicles, bushes); keep it below the width of the piles you measure (PDAL's default 18 m removes piles)",
    "ground_slope": "{opt:ground=filter}: steepest ground slope (rise/run) SMRF keeps as terrain (pile flanks; PDAL's default 0.15)",
    "exclude": "what is not soil: auto (points the signals say are not soil are not gridded: the LAS classification as {opt:ground} selects it, colour (vegetation by its excess-green index) and return numbers on files without one; objects that moved between the surveys are left out of the headline; objects in one survey only as {opt:objects} says), none (colour and returns not used, moved objects and objects in one survey only counted: the volumes {opt:exclude=auto} lists are restored; the class-2 selection stays with {opt:ground})",
    "objects": "objects in one survey only (a machine, a container, a cabin or a stack of materials that arrived or left, found by their near-vertical walls): exclude (left out of the headline and listed with their volume; only earthworks count), count (counted as fill or cut and listed: the seed paper's test pillars)",
    "lod_confidence": "confidence of the level of detection and of the volume uncertainty",
    "zones": "optional polygon file: volumes per polygon (a series with a design: its progress per polygon)",
    "design_uncertainty": "when BEFORE is a surface (a design DEM GeoTIFF): its vertical uncertainty (m, one sigma, common to the compared area), added to the volumes' interval; 0 takes the design as exact",
    "contour_interval": "write contours.gpkg: contour lines every this many metres of the difference (layer difference: ELEV below 0 is cut, above 0 fill, 0 their border) and of each DEM (layers dem_before, dem_after), by GDAL's contour algorithm, none across nodata (0 = none)",
    "sections": "a vector file of lines (any OGR format; its CRS honoured): a cross-section along each, the heights before (the design against a surface), after and their difference every half cell, in sections.csv (line id and name, chainage in m, x, y, before, after, difference) and one picture per line, sections/NAME.svg",
    "gpkg": "also write the areas of significant change as change_areas.gpkg and, with {opt:zones}, the zones with their budgets as zones.gpkg (GeoPackage, in the run's CRS; zones.csv is written with {opt:zones} either way)",
    "design_surface": "when BEFORE is a LandXML file: the name of its TIN surface to use (default: the file's first surface)",
    "bulking": "bulking (swell) factor, loose/bank volume (e.g. 1.25): report.json's quantities give the loose volumes (a zone's own: its 'bulking' attribute in the zones file)",
    "shrinkage": "shrinkage factor, compacted/bank volume (e.g. 0.90): report.json's quantities give the compacted volumes (a zone's own: its 'shrinkage' attribute in the zones file)",
    "tolerance": "when BEFORE is a design: the on-grade tolerance (m, e.g. 0.05): grade.tif classes each cell as cut to go (survey above design by more than it), on grade or fill to go; report.json's grade gives the share on grade and the cut and fill still to go, overall and per zone",
    "design": "a series' design surface (a DEM GeoTIFF or a LandXML TIN), resampled onto the series' grid: with {opt:tolerance}, each epoch's share on grade and cut and fill still to go, and each period's progress (the cut and fill to go it did)",
    # the stockpile inventory and the run control (where and how a run goes, never its numbers)
    "base": "what each pile's volume is measured from: triangulated (a surface through its toe line, the common practice), plane (a plane fit to the toe), lowest, average or highest (a level at the toe's lowest, mean or highest height), elevation:Z (a level at Z metres, the survey's heights), surface:DEM (a GeoTIFF such as an earlier survey's DEM or a design, resampled onto the grid)",
    "density": "bulk density (t/m3) for tonnage, for every pile without its own density field",
    "threads": "worker threads of the registration (its nearest-neighbour searches and Open3D; 0 = all cores)",
    "scheduler": "where the work runs: none (in-process), threads[:N] (tiles on N threads), local[:N] (tiles on a Dask LocalCluster of N worker processes), tcp://HOST[:PORT] (an existing Dask cluster, port 8786 by default; its workers must see the input paths), auto (in-process when the pair fits {opt:memory_limit}, else local)",
    "memory_limit": "memory budget (GB) of the run: auto chooses in-process below it, and a LocalCluster shares it among its workers, at least 0.25 GB each (0 = half of this machine's memory)",
    "tile_cells": "side (cells) of the tiles the distributed engine grids one task at a time (0 = from the point density: what half of a worker's share of {opt:memory_limit} holds, at most 32 million points, at least two tiles per worker, snapped to a VPC's tiles when one fits)",
    "volume_step": "where a distributed run's volume step (holes, correction, change areas, uncertainty) runs: whole (the whole grid in the driver process; results equal the in-process run), tiles (tile by tile on the workers with halos, the correction and stable ground found on an overview of the grid; for grids too large for one process), auto (tiles when the grid exceeds half of {opt:memory_limit})",
    "keep_registered_cloud": "write after_registered.laz (the after cloud moved by the registration; the transform is always in report.json)",
}


@options(HELP)
class Options:
    """Options of one run (all lengths in metres of the before CRS), by topic in table order."""

    # inputs
    before_crs: str | None = option(None, "Before CRS override", PREPARE)
    after_crs: str | None = option(None, "After CRS override", PREPARE)
    # step 1: alignment initialisation
    radius: float = option(30.0, "Crop radius around the after footprint", PREPARE, "m", 0.0, 10000.0)
    # step 2: coarse registration
    coarse: str = option("auto", "Coarse registration", REGISTER, choices=("auto", "fpfh", "none"))
    coarse_voxel: float = option(1.0, "Coarse registration voxel", REGISTER, "m", 0.05, 100.0)
    georeferencing: str = option("auto", "Georeferencing of the surveys", REGISTER, choices=("auto", "gps", "precise"))
    max_gps_shift: float = option(8.0, "Georeferencing prior: largest shift", REGISTER, "m", 0.0, 1000.0)
    max_gps_rotation: float = option(6.0, "Georeferencing prior: largest rotation", REGISTER, "deg", 0.0, 180.0)
    max_gps_tilt: float = option(1.0, "Georeferencing prior: largest tilt", REGISTER, "deg", 0.0, 90.0)
    # step 3: fine registration
    fine: str = option("icp", "Fine registration", REGISTER, choices=("icp", "gicp", "pfh", "none"))
    pfh_patch: float = option(6.0, "PFH patch size", REGISTER, "m", 0.5, 1000.0)
    seed: int = option(0, "Random seed", REGISTER, None, 0, 2**31 - 1)
    # step 4: plane-offset / bias compensation
    correction: str = option(
        "surface", "Vertical bias correction", VOLUME, choices=("surface", "plane", "paper-plane", "none")
    )
    plane_threshold: float = option(0.15, "RANSAC plane inlier distance", VOLUME, "m", 0.001, 100.0)
    stable_mask: str | None = option(None, "Stable ground polygons", VOLUME)
    # step 5: grids and volumes
    cell: float | None = option(None, "Grid cell size", GRID, "m", 0.01, 1000.0)
    statistic: str = option("robust-mean", "Per-cell height statistic", GRID, choices=("robust-mean", "mean", "median"))
    min_count_ratio: float = option(0.1, "Weak cell threshold (fraction of the median count)", CELLS, None, 0.0, 1.0)
    fill_holes: float = option(100.0, "Largest hole to fill", VOLUME, "m2", 0.0, 1e7)
    fill_method: str = option("biharmonic", "Hole interpolation", VOLUME, choices=("biharmonic", "harmonic"))
    ground: str = option("auto", "Ground points", GROUND, choices=("auto", "class", "filter", "csf", "none"))
    ground_window: float = option(6.0, "Ground filter window", GROUND, "m", 0.5, 500.0)
    ground_slope: float = option(0.6, "Ground filter slope (rise/run)", GROUND, None, 0.01, 10.0)
    exclude: str = option("auto", "Exclude what is not soil", POINTS, choices=("auto", "none"))
    objects: str = option("exclude", "Objects in one survey only", VOLUME, choices=("exclude", "count"))
    lod_confidence: float = option(0.95, "Confidence level", VOLUME, None, 0.5, 0.999)
    zones: str | None = option(None, "Zones (polygons)", DESIGNED)
    design_uncertainty: float = option(0.0, "Design uncertainty (a surface as BEFORE)", ESTIMATE, "m", 0.0, 100.0)
    contour_interval: float = option(0.0, "Contour interval", ESTIMATE, "m", 0.0, 10000.0, run_control=True)
    sections: str | None = option(None, "Cross-section lines", run_control=True)
    gpkg: bool = option(False, "GeoPackage copies of the change areas and zones", run_control=True)
    design_surface: str | None = option(None, "LandXML surface name (a LandXML design as BEFORE)", DESIGNED)
    bulking: float | None = option(None, "Bulking factor (loose/bank)", VOLUME, None, 0.0, 10.0, lo_open=True)
    shrinkage: float | None = option(None, "Shrinkage factor (compacted/bank)", VOLUME, None, 0.0, 10.0, lo_open=True)
    tolerance: float | None = option(
        None, "On-grade tolerance (a design as BEFORE)", DESIGNED, "m", 0.0, 100.0, lo_open=True
    )
    design: str | None = option(None, "Design surface (a series' progress)", ("series",))
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

    def with_(self, **changes: Any) -> Options:
        """A copy with some fields changed."""
        return replace(self, **changes)


def command_fields(command: str) -> list[Field]:
    """The option fields ``command`` takes, in table order."""
    if command not in COMMANDS:
        raise ValueError(f"unknown command {command!r}")
    return [f for f in fields(Options) if command in f.metadata["commands"]]
