"""Every knob of the pipeline in one dataclass, with defaults and one-line docs.

The CLI builds its ``--help`` from the ``help`` metadata here, the QGIS algorithms map their
parameters onto the same fields, so all front ends share one set of defaults.
"""

from __future__ import annotations

from dataclasses import Field, dataclass, field, fields, replace
from typing import Any

#: which commands take an option (``commands=`` of each field below): the command line builds
#: each subcommand's flags from it and the QGIS algorithms their parameters
ESTIMATE = ("estimate",)
VOLUME = ("estimate", "series")  # the volume step (a series runs it once per later epoch)
REGISTER = ("estimate", "register", "series")
PREPARE = ("estimate", "register", "pipeline", "series")  # reading both clouds
GRID = ("estimate", "dem", "series", "stockpile")
GROUND = ("estimate", "register", "dem", "pipeline", "series", "stockpile")
GROUND_FILTER = ("estimate", "register", "dem", "series", "pipeline", "stockpile")
POINTS = ("estimate", "register", "dem", "series", "stockpile")  # what is read of each cloud (the soil rule)
CELLS = ("estimate", "dem", "series")  # the heights of each cell
STOCKPILE = ("stockpile",)  # one survey's stockpile inventory
COMMANDS = ("estimate", "register", "dem", "pipeline", "series", "stockpile")


def _opt(
    default: Any,
    help: str,
    choices: tuple | None = None,
    *,
    label: str | None = None,
    unit: str | None = None,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    commands: tuple[str, ...] = ESTIMATE,
    run_control: bool = False,
) -> Any:
    """An option: default, one-line help, choices; ``label`` (short title for GUIs), ``unit``
    ("m", "m2", "deg", ...), the allowed range ``lo``..``hi`` (``lo`` excluded when
    ``lo_open``) that every front end validates against, the ``commands`` that take it, and
    ``run_control``: where and how the run goes, never its numbers (every other option keys the
    work a resumed run may reuse)."""
    meta = {"help": help, "choices": choices, "label": label, "unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open}
    return field(default=default, metadata={**meta, "commands": commands, "run_control": run_control})


@dataclass(frozen=True)
class Options:
    """Options of one estimate run (all lengths in metres of the before CRS)."""

    # inputs
    before_crs: str | None = _opt(
        None,
        "CRS of the before cloud when its header has none (e.g. EPSG:32654 or EPSG:2991+6360)",
        label="Before CRS override",
        commands=PREPARE,
    )
    after_crs: str | None = _opt(
        None, "CRS of the after cloud when its header has none", label="After CRS override", commands=PREPARE
    )
    # step 1: alignment initialisation
    radius: float = _opt(
        30.0,
        "crop radius (m) around the after cloud's footprint applied to the before cloud (paper: 30 m)",
        label="Crop radius around the after footprint",
        unit="m",
        lo=0.0,
        hi=10000.0,
        commands=PREPARE,
    )
    # step 2: coarse registration
    coarse: str = _opt(
        "auto",
        "coarse registration: auto (FPFH+RANSAC only when the fine stage from the GPS pose fits poorly, kept only within the GPS error prior and if it then fits better), fpfh (always, the paper's path), none",
        ("auto", "fpfh", "none"),
        label="Coarse registration",
        commands=REGISTER,
    )
    coarse_voxel: float = _opt(
        1.0,
        "voxel size (m) for FPFH features and RANSAC",
        label="Coarse registration voxel",
        unit="m",
        lo=0.05,
        hi=100.0,
        commands=REGISTER,
    )
    georeferencing: str = _opt(
        "auto",
        "how far the surveys' georeferencing is trusted: auto (gps, unless both files declare the same vertical datum and the registration confirms their coordinates: its pose within its own resolution of them, then precise; a declared datum alone proves nothing), gps (GPS-tagged UAV surveys: registered within the prior below), precise (LiDAR, RTK/PPK or ground control: coordinates used as they are, no registration and no bias correction)",
        ("auto", "gps", "precise"),
        label="Georeferencing of the surveys",
        commands=REGISTER,
    )
    max_gps_shift: float = _opt(
        8.0,
        "georeferencing prior: largest shift (m) registration may apply",
        label="Georeferencing prior: largest shift",
        unit="m",
        lo=0.0,
        hi=1000.0,
        commands=REGISTER,
    )
    max_gps_rotation: float = _opt(
        6.0,
        "georeferencing prior: largest rotation (degrees, mostly yaw) registration may apply",
        label="Georeferencing prior: largest rotation",
        unit="deg",
        lo=0.0,
        hi=180.0,
        commands=REGISTER,
    )
    max_gps_tilt: float = _opt(
        1.0,
        "georeferencing prior: largest tilt (degrees, about a horizontal axis) registration may apply; a tilt the stable ground cannot pin down stays at 0",
        label="Georeferencing prior: largest tilt",
        unit="deg",
        lo=0.0,
        hi=90.0,
        commands=REGISTER,
    )
    # step 3: fine registration
    fine: str = _opt(
        "icp",
        "fine registration: icp (robust point-to-plane, coarse-to-fine, change areas down-weighted), gicp, pfh (the paper's PFH + SAC-IA on a patch), none",
        ("icp", "gicp", "pfh", "none"),
        label="Fine registration",
        commands=REGISTER,
    )
    pfh_patch: float = _opt(
        6.0,
        "side (m) of the square patch used by {opt:fine=pfh} (paper: 6 m)",
        label="PFH patch size",
        unit="m",
        lo=0.5,
        hi=1000.0,
        commands=REGISTER,
    )
    seed: int = _opt(
        0,
        "random seed for every RANSAC/sampling step (results are deterministic)",
        label="Random seed",
        lo=0,
        hi=2**31 - 1,
        commands=REGISTER,
    )
    # step 4: plane-offset / bias compensation
    correction: str = _opt(
        "surface",
        "vertical bias correction: surface (degree-2 polynomial on stable ground), plane (plane on stable ground), paper-plane (the paper's two RANSAC planes, d_i), none",
        ("surface", "plane", "paper-plane", "none"),
        label="Vertical bias correction",
        commands=VOLUME,
    )
    plane_threshold: float = _opt(
        0.15,
        "RANSAC plane inlier distance (m)",
        label="RANSAC plane inlier distance",
        unit="m",
        lo=0.001,
        hi=100.0,
        commands=VOLUME,
    )
    stable_mask: str | None = _opt(
        None,
        "optional polygon file (GeoPackage/Shapefile/GeoJSON) of ground known to be stable",
        label="Stable ground polygons",
        commands=VOLUME,
    )
    # step 5: grids and volumes
    cell: float | None = _opt(
        None,
        "grid cell size (m); default from the before cloud's density (>= 8 points per cell, >= 0.5 m)",
        label="Grid cell size",
        unit="m",
        lo=0.01,
        hi=1000.0,
        commands=GRID,
    )
    statistic: str = _opt(
        "robust-mean",
        "per-cell height: robust-mean (mean after rejecting points beyond 3 MAD of the cell median), mean (the paper), median",
        ("robust-mean", "mean", "median"),
        label="Per-cell height statistic",
        commands=GRID,
    )
    min_count_ratio: float = _opt(
        0.1,
        "a cell of one epoch with fewer points than this fraction of its median count (and always one with fewer than 3) is unreliable: its height is re-filled from neighbours (0 = off)",
        label="Weak cell threshold (fraction of the median count)",
        lo=0.0,
        hi=1.0,
        commands=CELLS,
    )
    fill_holes: float = _opt(
        100.0,
        "fill enclosed holes (cells empty in either epoch, e.g. occlusions) up to this area (m2) by interpolating the height difference around them; larger holes stay empty and are reported (0 = off)",
        label="Largest hole to fill",
        unit="m2",
        lo=0.0,
        hi=1e7,
        commands=VOLUME,
    )
    fill_method: str = _opt(
        "biharmonic",
        "interpolation of refilled cells: biharmonic (smooth, keeps slopes across the hole), harmonic (Laplace, never overshoots its border values)",
        ("biharmonic", "harmonic"),
        label="Hole interpolation",
        commands=VOLUME,
    )
    ground: str = _opt(
        "auto",
        "ground points: auto (class 2 when the file has ground-classified points, judged on its first million points; else all), class (class 2 only), filter (SMRF ground filter), csf (cloth simulation filter, tuned for earthworks: a 0.5 m cloth of medium stiffness that follows piles and pits and bridges vehicles and bushes; needs the cloth-simulation-filter package), none",
        ("auto", "class", "filter", "csf", "none"),
        label="Ground points",
        commands=GROUND,
    )
    ground_window: float = _opt(
        6.0,
        "{opt:ground=filter}: largest object (m) the SMRF filter removes (vehicles, bushes); keep it below the width of the piles you measure (PDAL's default 18 m removes piles)",
        label="Ground filter window",
        unit="m",
        lo=0.5,
        hi=500.0,
        commands=GROUND_FILTER,
    )
    ground_slope: float = _opt(
        0.6,
        "{opt:ground=filter}: steepest ground slope (rise/run) SMRF keeps as terrain (pile flanks; PDAL's default 0.15)",
        label="Ground filter slope (rise/run)",
        lo=0.01,
        hi=10.0,
        commands=GROUND_FILTER,
    )
    exclude: str = _opt(
        "auto",
        "what is not soil: auto (points the signals say are not soil are not gridded: the LAS classification as {opt:ground} selects it, colour (vegetation by its excess-green index) and return numbers on files without one; objects that moved between the surveys are left out of the headline; objects in one survey only as {opt:objects} says), none (colour and returns not used, moved objects and objects in one survey only counted: the volumes {opt:exclude=auto} lists are restored; the class-2 selection stays with {opt:ground})",
        ("auto", "none"),
        label="Exclude what is not soil",
        commands=POINTS,
    )
    objects: str = _opt(
        "exclude",
        "objects in one survey only (a machine, a container, a cabin or a stack of materials that arrived or left, found by their near-vertical walls): exclude (left out of the headline and listed with their volume; only earthworks count), count (counted as fill or cut and listed: the seed paper's test pillars)",
        ("exclude", "count"),
        label="Objects in one survey only",
        commands=VOLUME,
    )
    lod_confidence: float = _opt(
        0.95,
        "confidence of the level of detection and of the volume uncertainty",
        label="Confidence level",
        lo=0.5,
        hi=0.999,
        commands=VOLUME,
    )
    zones: str | None = _opt(None, "optional polygon file: volumes per polygon", label="Zones (polygons)")
    design_uncertainty: float = _opt(
        0.0,
        "when BEFORE is a surface (a design DEM GeoTIFF): its vertical uncertainty (m, one sigma, common to the "
        "compared area), added to the volumes' interval; 0 takes the design as exact",
        label="Design uncertainty (a surface as BEFORE)",
        unit="m",
        lo=0.0,
        hi=100.0,
    )
    contour_interval: float = _opt(
        0.0,
        "write contours.gpkg: contour lines every this many metres of the difference (layer difference: ELEV below 0 "
        "is cut, above 0 fill, 0 their border) and of each DEM (layers dem_before, dem_after), by GDAL's contour "
        "algorithm, none across nodata (0 = none)",
        label="Contour interval",
        unit="m",
        lo=0.0,
        hi=10000.0,
        run_control=True,
    )
    sections: str | None = _opt(
        None,
        "a vector file of lines (any OGR format; its CRS honoured): a cross-section along each, the heights before "
        "(the design against a surface), after and their difference every half cell, in sections.csv (line id and "
        "name, chainage in m, x, y, before, after, difference) and one picture per line, sections/NAME.svg",
        label="Cross-section lines",
        run_control=True,
    )
    design_surface: str | None = _opt(
        None,
        "when BEFORE is a LandXML file: the name of its TIN surface to use (default: the file's first surface)",
        label="LandXML surface name (a LandXML design as BEFORE)",
    )
    bulking: float | None = _opt(
        None,
        "bulking (swell) factor, loose/bank volume (e.g. 1.25): report.json's quantities give the loose volumes "
        "(a zone's own: its 'bulking' attribute in the zones file)",
        label="Bulking factor (loose/bank)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
        commands=VOLUME,
    )
    shrinkage: float | None = _opt(
        None,
        "shrinkage factor, compacted/bank volume (e.g. 0.90): report.json's quantities give the compacted volumes "
        "(a zone's own: its 'shrinkage' attribute in the zones file)",
        label="Shrinkage factor (compacted/bank)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
        commands=VOLUME,
    )
    tolerance: float | None = _opt(
        None,
        "when BEFORE is a design: the on-grade tolerance (m, e.g. 0.05): grade.tif classes each cell as cut to go "
        "(survey above design by more than it), on grade or fill to go; report.json's grade gives the share on "
        "grade and the cut and fill still to go, overall and per zone",
        label="On-grade tolerance (a design as BEFORE)",
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=100.0,
    )
    # stockpile inventory
    base: str = _opt(
        "triangulated",
        "what each pile's volume is measured from: triangulated (a surface through its toe line, the common "
        "practice), plane (a plane fit to the toe), lowest, average or highest (a level at the toe's lowest, mean or "
        "highest height), elevation:Z (a level at Z metres, the survey's heights), surface:DEM (a GeoTIFF such as an "
        "earlier survey's DEM or a design, resampled onto the grid)",
        label="Stockpile base surface",
        commands=STOCKPILE,
    )
    density: float | None = _opt(
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
    threads: int = _opt(
        0,
        "worker threads of the registration (its nearest-neighbour searches and Open3D; 0 = all cores)",
        label="Threads",
        lo=0,
        hi=1024,
        commands=REGISTER,
        run_control=True,
    )
    scheduler: str = _opt(
        "auto",
        "where the work runs: none (in-process), threads[:N] (tiles on N threads), local[:N] (tiles on a Dask LocalCluster of N worker processes), tcp://HOST[:PORT] (an existing Dask cluster, port 8786 by default; its workers must see the input paths), auto (in-process when the pair fits {opt:memory_limit}, else local)",
        label="Scheduler",
        run_control=True,
    )
    memory_limit: float = _opt(
        0.0,
        "memory budget (GB) of the run: auto chooses in-process below it, and a LocalCluster shares it among its workers, at least 0.25 GB each (0 = half of this machine's memory)",
        label="Memory budget",
        unit="GB",
        lo=0.0,
        hi=1e6,
        run_control=True,
    )
    tile_cells: int = _opt(
        0,
        "side (cells) of the tiles the distributed engine grids one task at a time (0 = from the point density: what half of a worker's share of {opt:memory_limit} holds, at most 32 million points, at least two tiles per worker, snapped to a VPC's tiles when one fits)",
        label="Tile size",
        unit="cells",
        lo=0,
        hi=100000,
    )
    volume_step: str = _opt(
        "auto",
        "where a distributed run's volume step (holes, correction, change areas, uncertainty) runs: whole (the whole grid in the driver process; results equal the in-process run), tiles (tile by tile on the workers with halos, the correction and stable ground found on an overview of the grid; for grids too large for one process), auto (tiles when the grid exceeds half of {opt:memory_limit})",
        ("auto", "whole", "tiles"),
        label="Volume step",
    )
    keep_registered_cloud: bool = _opt(
        False,
        "write after_registered.laz (the after cloud moved by the registration; the transform is always in report.json)",
        label="Write the registered after cloud",
        run_control=True,
    )

    def with_(self, **changes: Any) -> Options:
        """A copy with some fields changed."""
        return replace(self, **changes)


def command_fields(command: str) -> list[Field]:
    """The option fields ``command`` takes, in table order."""
    if command not in COMMANDS:
        raise ValueError(f"unknown command {command!r}")
    return [f for f in fields(Options) if command in f.metadata["commands"]]
