"""Steps 1-4: alignment initialisation, coarse and fine registration, the plane-offset correction."""

from __future__ import annotations

from dataclasses import dataclass

from .table import PREPARE, REGISTER, VOLUME, option


@dataclass(frozen=True)
class RegistrationOptions:
    """Steps 1-4: alignment initialisation, coarse and fine registration, the plane-offset correction."""

    # step 1: alignment initialisation
    radius: float = option(
        30.0,
        "crop radius (m) around the after cloud's footprint applied to the before cloud (paper: 30 m)",
        label="Crop radius around the after footprint",
        unit="m",
        lo=0.0,
        hi=10000.0,
        commands=PREPARE,
    )
    # step 2: coarse registration
    coarse: str = option(
        "auto",
        "coarse registration: auto (FPFH+RANSAC only when the fine stage from the GPS pose fits poorly, kept only within the GPS error prior and if it then fits better), fpfh (always, the paper's path), none",
        ("auto", "fpfh", "none"),
        label="Coarse registration",
        commands=REGISTER,
    )
    coarse_voxel: float = option(
        1.0,
        "voxel size (m) for FPFH features and RANSAC",
        label="Coarse registration voxel",
        unit="m",
        lo=0.05,
        hi=100.0,
        commands=REGISTER,
    )
    georeferencing: str = option(
        "auto",
        "how far the surveys' georeferencing is trusted: auto (gps, unless both files declare the same vertical datum and the registration confirms their coordinates: its pose within its own resolution of them, then precise; a declared datum alone proves nothing), gps (GPS-tagged UAV surveys: registered within the prior below), precise (LiDAR, RTK/PPK or ground control: coordinates used as they are, no registration and no bias correction)",
        ("auto", "gps", "precise"),
        label="Georeferencing of the surveys",
        commands=REGISTER,
    )
    max_gps_shift: float = option(
        8.0,
        "georeferencing prior: largest shift (m) registration may apply",
        label="Georeferencing prior: largest shift",
        unit="m",
        lo=0.0,
        hi=1000.0,
        commands=REGISTER,
    )
    max_gps_rotation: float = option(
        6.0,
        "georeferencing prior: largest rotation (degrees, mostly yaw) registration may apply",
        label="Georeferencing prior: largest rotation",
        unit="deg",
        lo=0.0,
        hi=180.0,
        commands=REGISTER,
    )
    max_gps_tilt: float = option(
        1.0,
        "georeferencing prior: largest tilt (degrees, about a horizontal axis) registration may apply; a tilt the stable ground cannot pin down stays at 0",
        label="Georeferencing prior: largest tilt",
        unit="deg",
        lo=0.0,
        hi=90.0,
        commands=REGISTER,
    )
    # step 3: fine registration
    fine: str = option(
        "icp",
        "fine registration: icp (robust point-to-plane, coarse-to-fine, change areas down-weighted), gicp, pfh (the paper's PFH + SAC-IA on a patch), none",
        ("icp", "gicp", "pfh", "none"),
        label="Fine registration",
        commands=REGISTER,
    )
    pfh_patch: float = option(
        6.0,
        "side (m) of the square patch used by {opt:fine=pfh} (paper: 6 m)",
        label="PFH patch size",
        unit="m",
        lo=0.5,
        hi=1000.0,
        commands=REGISTER,
    )
    seed: int = option(
        0,
        "random seed for every RANSAC/sampling step (results are deterministic)",
        label="Random seed",
        lo=0,
        hi=2**31 - 1,
        commands=REGISTER,
    )
    # step 4: plane-offset / bias compensation
    correction: str = option(
        "surface",
        "vertical bias correction: surface (degree-2 polynomial on stable ground), plane (plane on stable ground), paper-plane (the paper's two RANSAC planes, d_i), none",
        ("surface", "plane", "paper-plane", "none"),
        label="Vertical bias correction",
        commands=VOLUME,
    )
    plane_threshold: float = option(
        0.15,
        "RANSAC plane inlier distance (m)",
        label="RANSAC plane inlier distance",
        unit="m",
        lo=0.001,
        hi=100.0,
        commands=VOLUME,
    )
    stable_mask: str | None = option(
        None,
        "optional polygon file (GeoPackage/Shapefile/GeoJSON) of ground known to be stable",
        label="Stable ground polygons",
        commands=VOLUME,
    )
