"""How far the surveys' georeferencing is trusted: ``gps`` (register within the prior),
``precise`` (use the coordinates as they are), or ``auto`` (precise when both files declare the
same vertical datum and already agree at the margin of the after survey, else gps)."""

from __future__ import annotations

import numpy as np
import pyproj

from ..core.wording import opt

AGREE_FITNESS = 0.6  # share of the margin within 0.4 m of the before surface at the given pose


def vertical_datum(wkt: str | None) -> str | None:
    """Name of the vertical CRS a file declares (compound CRS), None when it has none."""
    if not wkt:
        return None
    try:
        crs = pyproj.CRS.from_wkt(wkt)
    except pyproj.exceptions.CRSError:
        return None
    if crs.is_compound and len(crs.sub_crs_list) > 1 and crs.sub_crs_list[1].is_vertical:
        return crs.sub_crs_list[1].name
    return None


def resolve(mode: str, inputs: dict, after_xyz: np.ndarray, before_xyz: np.ndarray) -> tuple[str, str]:
    """(``gps`` or ``precise``, the reason in plain words) for the run."""
    if mode != "auto":
        return mode, opt("georeferencing", mode)
    vb = vertical_datum(inputs["before"].get("crs_wkt"))
    va = vertical_datum(inputs["after"].get("crs_wkt"))
    if vb is None or vb != va:
        return "gps", "the files do not both declare the same vertical datum: registered within the GPS prior"
    from .ground import margin_points, spacing
    from .register import evaluate_surface

    gap = spacing(before_xyz)
    fit, _ = evaluate_surface(margin_points(after_xyz, gap), before_xyz, np.eye(4), gap=gap)
    if fit < AGREE_FITNESS:
        return "gps", (
            f"both files declare {vb}, but only {fit:.0%} of the after survey's margin agrees with "
            "the before surface as georeferenced: registered within the GPS prior"
        )
    return "precise", (
        f"both files declare {vb} and {fit:.0%} of the after survey's margin agrees with the "
        "before surface as georeferenced: coordinates used as they are (no registration, no "
        f"bias correction); use {opt('georeferencing', 'gps')} to register anyway"
    )
