"""The quality gate's (severity, sentence) checks of how the after survey was placed (report.json's
``registration``): a registered run's, or a georeferenced one's ground outside the works."""

from __future__ import annotations

import numpy as np

from ..compensation.stable import largest_gap_deg
from ..core.wording import opt
from ..registration.georef import GROUND_AGREES, INCONCLUSIVE, disagreement

MIN_STABLE_FRACTION = 0.05  # less stable ground than this share of the compared area: not reliable
LOW_STABLE_FRACTION = 0.1  # less than this: use with caution (a site whose works cover most of it)
MIN_STABLE_CELLS = 30
PRIOR_MARGIN = 0.8  # a pose using more than this share of the prior is suspicious


def registration_checks(
    reg: dict, stable: np.ndarray, change: np.ndarray, offset: np.ndarray, prior: dict, diff: np.ndarray | None
) -> list[tuple[str, str]]:
    """A registered run's checks (stable ground, prior, fit) or a georeferenced one's."""
    used = reg.get("georeferencing", {}).get("used", "gps")
    if used == "gps":
        return _stable_checks(stable, change, offset) + _prior_checks(reg, prior)
    return _precise_checks(reg, stable, diff) if used == "precise" else []


def _stable_checks(stable: np.ndarray, change: np.ndarray, offset: np.ndarray) -> list[tuple[str, str]]:
    """Enough stable ground, and around the works."""
    n_stable, n_valid = int(stable.sum()), max(int(np.isfinite(offset).sum()), 1)
    share = n_stable / n_valid
    if n_stable < MIN_STABLE_CELLS or share < MIN_STABLE_FRACTION:
        said = f"too little stable ground ({share:.0%} of the compared area) to register the surveys and remove "
        return [("unreliable", said + "their bias: the works may have been absorbed")]
    if share < LOW_STABLE_FRACTION:
        said = f"little stable ground ({share:.0%} of the compared area): the registration and bias correction "
        return [("caution", said + "rest on it alone; check that they did not absorb the works")]
    if largest_gap_deg(stable, change) > 180:
        said = "the stable ground lies on one side of the works only: tilt and bias across the works are extrapolated"
        return [("caution", said)]
    return []


def _prior_checks(reg: dict, prior: dict) -> list[tuple[str, str]]:
    """The pose within the georeferencing prior, the fit of the after survey."""
    out: list[tuple[str, str]] = []
    for key, limit, unit in (
        ("rotation_deg", prior["rotation"], "deg"),
        ("tilt_deg", prior["tilt"], "deg"),
        ("shift_m", prior["shift"], "m"),
    ):
        val = reg.get(key, 0.0)
        if limit > 0 and val > PRIOR_MARGIN * limit:
            said = f"the registration used {val:.2f} {unit} of a {limit:g} {unit} georeferencing prior"
            out.append(("caution", f"{said} ({key.split('_')[0]})"))
    if reg.get("fine", {}).get("poses_beyond_prior", 0) > 0:  # registration's count, not its wording
        said = "registration wanted a pose beyond the georeferencing prior (the works may pull it); the best pose"
        out.append(("caution", said + " within the prior was kept"))
    fit = reg.get("fine", {}).get("fitness")
    if fit is not None and np.isfinite(fit) and fit < 0.5:
        out.append(("caution", f"only {fit:.0%} of the after survey fits the before surface after registration"))
    return out


def _precise_checks(reg: dict, stable: np.ndarray, diff: np.ndarray | None) -> list:
    """A georeferenced run's: the ground outside the works agrees, the coordinates confirmed."""
    out: list[tuple[str, str]] = []
    check = (reg.get("georeferencing") or {}).get("check") or {}
    if check.get("outcome") == INCONCLUSIVE:
        said = (
            f"the registration could not confirm the files' coordinates ({disagreement(check)}): they were "
            "used as georeferenced because both declare one vertical datum and the after survey's margin agrees"
        )
        out.append(("caution", said))
    ground = diff[stable & np.isfinite(diff)] if diff is not None else np.empty(0)
    shift = float(np.median(ground)) if ground.size else 0.0
    if abs(shift) > GROUND_AGREES:
        said = (
            f"the ground outside the change areas differs by {shift:+.2f} m between the surveys and was not "
            f"corrected (coordinates used as georeferenced): check the datums, or use {opt('georeferencing', 'gps')}"
        )
        out.append(("caution", f"{said} if it is a survey offset"))
    return out
