"""Steps 1-4: alignment initialisation, coarse and fine registration, the plane-offset correction."""

from __future__ import annotations

from .table import PREPARE, REGISTER, VOLUME, option, options

HELP = {
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
}


@options(HELP)
class RegistrationOptions:
    """Steps 1-4: alignment initialisation, coarse and fine registration, the plane-offset correction."""

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
