"""Every knob of the pipeline in one dataclass, with defaults and one-line docs.

The CLI builds its ``--help`` from the ``help`` metadata here, the QGIS algorithms map their
parameters onto the same fields, so all front ends share one set of defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any


def _opt(default: Any, help: str, choices: tuple | None = None) -> Any:
    return field(default=default, metadata={"help": help, "choices": choices})


@dataclass(frozen=True)
class Options:
    """Options of one estimate run (all lengths in metres of the before CRS)."""

    # inputs
    before_crs: str | None = _opt(None, "CRS of the before cloud when its header has none (e.g. EPSG:32654 or EPSG:2991+6360)")
    after_crs: str | None = _opt(None, "CRS of the after cloud when its header has none")
    # step 1: alignment initialisation
    radius: float = _opt(30.0, "crop radius (m) around the after cloud's footprint applied to the before cloud (paper: 30 m)")
    # step 2: coarse registration
    coarse: str = _opt("auto", "coarse registration: auto (FPFH+RANSAC only when the fine stage from the GPS pose fits poorly, kept only within the GPS error prior and if it then fits better), fpfh (always, the paper's path), none", ("auto", "fpfh", "none"))
    coarse_voxel: float = _opt(1.0, "voxel size (m) for FPFH features and RANSAC")
    max_gps_shift: float = _opt(8.0, "GPS error prior: largest horizontal/vertical shift (m) a coarse result may apply")
    max_gps_rotation: float = _opt(6.0, "GPS error prior: largest rotation (degrees) a coarse result may apply")
    # step 3: fine registration
    fine: str = _opt("icp", "fine registration: icp (robust point-to-plane, coarse-to-fine, change areas down-weighted), gicp, pfh (the paper's PFH + SAC-IA on a patch), none", ("icp", "gicp", "pfh", "none"))
    pfh_patch: float = _opt(6.0, "side (m) of the square patch used by --fine pfh (paper: 6 m)")
    seed: int = _opt(0, "random seed for every RANSAC/sampling step (results are deterministic)")
    # step 4: plane-offset / bias compensation
    correction: str = _opt("surface", "vertical bias correction: surface (degree-2 polynomial on stable ground), plane (plane on stable ground), paper-plane (the paper's two RANSAC planes, d_i), none", ("surface", "plane", "paper-plane", "none"))
    plane_threshold: float = _opt(0.15, "RANSAC plane inlier distance (m)")
    stable_mask: str | None = _opt(None, "optional polygon file (GeoPackage/Shapefile/GeoJSON) of ground known to be stable")
    # step 5: grids and volumes
    cell: float | None = _opt(None, "grid cell size (m); default from the before cloud's density (>= 8 points per cell, >= 0.5 m)")
    statistic: str = _opt("robust-mean", "per-cell height: robust-mean (mean after rejecting points beyond 3 MAD of the cell median), mean (the paper), median", ("robust-mean", "mean", "median"))
    min_count_ratio: float = _opt(0.1, "a cell of one epoch with fewer points than this fraction of its median count (and always one with fewer than 3) is unreliable: its height is re-filled from neighbours (0 = off)")
    fill_holes: float = _opt(100.0, "fill enclosed holes (cells empty in either epoch, e.g. occlusions) up to this area (m2) by interpolating the height difference around them; larger holes stay empty and are reported (0 = off)")
    fill_method: str = _opt("biharmonic", "interpolation of refilled cells: biharmonic (smooth, keeps slopes across the hole), harmonic (Laplace, never overshoots its border values)", ("biharmonic", "harmonic"))
    ground: str = _opt("auto", "ground points: auto (class 2 when the file has ground-classified points, judged on its first million points; else all), class (class 2 only), filter (SMRF ground filter), none", ("auto", "class", "filter", "none"))
    ground_window: float = _opt(6.0, "--ground filter: largest object (m) the SMRF filter removes (vehicles, bushes); keep it below the width of the piles you measure (PDAL's default 18 m removes piles)")
    ground_slope: float = _opt(0.6, "--ground filter: steepest ground slope (rise/run) SMRF keeps as terrain (pile flanks; PDAL's default 0.15)")
    lod_confidence: float = _opt(0.95, "confidence of the level of detection and of the volume uncertainty")
    zones: str | None = _opt(None, "optional polygon file: volumes per polygon")
    # run control
    threads: int = _opt(0, "worker threads for Open3D/numpy (0 = all cores)")
    keep_registered_cloud: bool = _opt(False, "write after_registered.laz (the after cloud moved by the registration; the transform is always in report.json)")

    def with_(self, **changes: Any) -> Options:
        """A copy with some fields changed."""
        return replace(self, **changes)

    @classmethod
    def describe(cls) -> list[tuple[str, Any, str, tuple | None]]:
        """(name, default, help, choices) for every option, for CLIs and docs."""
        return [(f.name, f.default, f.metadata["help"], f.metadata["choices"]) for f in fields(cls)]
