"""How far the surveys' georeferencing is trusted: ``gps`` (register within the prior), ``precise``
(the coordinates as they are) or ``auto``: gps unless both files declare one vertical datum; then
the registration decides (:func:`confirm`), since a declared datum is no proof of precise
coordinates. It keeps them when its pose stays within its own resolution of them at the after
centre: horizontally one side of the finest columns (:func:`.fine.finest_column`), vertically
:data:`GROUND_AGREES`, turned or tilted by no more than moves the farthest point that much. Its
precision is the spread of its own poses: when they agree within the same bounds and none wanted
more than the prior, a pose within the bounds confirms the coordinates, one beyond refutes them.
When they disagree, the coordinates are kept (with a caution) if the after survey's margin agrees
with the before surface as surveyed (:data:`AGREE_FITNESS`), else registered."""

from __future__ import annotations

import numpy as np
import pyproj

from ..core.wording import opt
from .fine import finest_column
from .ground import evaluate_surface, margin_points, spacing
from .rigid import rotation_deg, tilt_deg

AGREE_FITNESS = 0.6  # share of the margin within 0.4 m of the before surface at the given pose
GROUND_AGREES = 0.05  # m: a vertical move the surveys' ground is said to agree within
CONFIRMED, REFUTED, INCONCLUSIVE = "confirmed", "refuted", "inconclusive"
KEYS = ("rotation_deg", "tilt_deg", "horizontal_m", "vertical_m")  # how a pose departs from another


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


def declared(mode: str, inputs: dict) -> tuple[str, str] | None:
    """(``gps`` or ``precise``, the reason) when decided before registering; None when the
    registration must decide (:func:`confirm`)."""
    if mode != "auto":
        return mode, opt("georeferencing", mode)
    vb, va = (vertical_datum(inputs[k].get("crs_wkt")) for k in ("before", "after"))
    if vb is None or vb != va:
        return "gps", "the files do not both declare the same vertical datum: registered within the GPS prior"
    return None


def move_at(t: np.ndarray, centre: np.ndarray) -> dict[str, float]:
    """How a 4x4 departs from the identity (:data:`KEYS`), its moves taken at ``centre``."""
    d = t[:3, :3] @ centre + t[:3, 3] - centre
    return dict(zip(KEYS, (rotation_deg(t), tilt_deg(t), float(np.hypot(d[0], d[1])), float(abs(d[2]))), strict=True))


def tolerances(reg, after_xyz: np.ndarray, gap: float) -> dict:
    """The bounds (:data:`KEYS`) within which a pose equals the file coordinates, and the ``spread``:
    the largest departures of the fine stage's refined poses from the accepted one."""
    centre = after_xyz.mean(axis=0)
    radius = float(np.hypot(*(after_xyz[:, :2] - centre[:2]).T).max(initial=1.0))
    column = finest_column(after_xyz, gap)
    turn, lift = (float(np.degrees(np.arctan(x / radius))) for x in (column, GROUND_AGREES))
    bounds = dict(zip(KEYS, (turn, lift, column, GROUND_AGREES), strict=True))
    inv, moved = np.linalg.inv(reg.transform), reg.transform[:3, :3] @ centre + reg.transform[:3, 3]
    moves = [move_at(p @ inv, moved) for p in reg.fine.poses]
    spread = {k: max([0.0, *(d[k] for d in moves)]) for k in KEYS}
    return {**bounds, "spread": spread, "column_m": column, "radius_m": radius}


def outcome(reg, after_xyz: np.ndarray, gap: float, fine: str) -> dict:
    """``confirmed``, ``refuted`` or (not consistent) ``inconclusive``, with the figures behind it."""
    tol = tolerances(reg, after_xyz, gap)
    move = move_at(reg.transform, after_xyz.mean(axis=0))
    within = all(move[k] <= tol[k] for k in KEYS)
    agree = all(tol["spread"][k] <= tol[k] for k in KEYS)
    consistent = fine != "none" and reg.fine.beyond_prior == 0 and agree
    said = (CONFIRMED if within else REFUTED) if consistent else INCONCLUSIVE
    return {"outcome": said, "move": move, "tolerance": tol, "poses_beyond_prior": reg.fine.beyond_prior}


def disagreement(check: dict) -> str:
    """How far an inconsistent registration's poses lie apart, in words."""
    d = check["tolerance"]["spread"]
    return (
        f"its poses differ by up to {d['rotation_deg']:.2f}°, {d['horizontal_m']:.2f} m across and "
        f"{d['vertical_m']:.2f} m up or down; {check['poses_beyond_prior']} beyond the georeferencing prior"
    )


def confirm(reg, after_xyz: np.ndarray, before_xyz: np.ndarray, datum: str, fine: str) -> tuple[str, str, dict]:
    """auto with a shared vertical ``datum``: (``gps`` or ``precise``, the reason, the check)."""
    gap = spacing(before_xyz)
    check = outcome(reg, after_xyz, gap, fine)
    m, t = check["move"], check["tolerance"]
    said = (
        f"the registration moved the after survey's centre {m['horizontal_m']:.2f} m across and "
        f"{m['vertical_m']:.2f} m up or down, turned it {m['rotation_deg']:.2f}° and tilted it "
        f"{m['tilt_deg']:.2f}° (tolerances {t['horizontal_m']:.2f} m, {t['vertical_m']:.2f} m, "
        f"{t['rotation_deg']:.2f}° and {t['tilt_deg']:.2f}°)"
    )
    if check["outcome"] == CONFIRMED:
        why = f"both files declare {datum} and {said}, its poses agreeing: coordinates confirmed, used as they are"
        return "precise", why, check
    if check["outcome"] == REFUTED:
        why = f"both files declare {datum}, but {said}, its poses agreeing: the coordinates are off, registered"
        return "gps", why, check
    fit, _ = evaluate_surface(margin_points(after_xyz, gap), before_xyz, np.eye(4), gap=gap)
    check["margin_agreement"] = fit
    unsure = f"both files declare {datum} and {said}, but the registration is not consistent ({disagreement(check)})"
    if fit < AGREE_FITNESS:
        why = f"{unsure} and only {fit:.0%} of the after survey's margin agrees as georeferenced: registered"
        return "gps", why, check
    why = (
        f"{unsure}: it cannot confirm the coordinates; {fit:.0%} of the after survey's margin agrees "
        f"with the before surface as georeferenced: used as they are (no bias correction); use "
        f"{opt('georeferencing', 'gps')} to register anyway"
    )
    return "precise", why, check
