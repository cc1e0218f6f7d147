"""The quality gate's checks of how the after survey was placed (report.json's
``registration``): enough stable ground around the works, the pose within the georeferencing
prior and the fit of a registered run; the ground outside the works of a run used as
georeferenced. Each check is a (severity, sentence) pair (:mod:`.quality`)."""

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
    """The checks of how the after survey was placed (report.json's ``registration``): a
    registered run's (:func:`_gps_checks`) or a run used as georeferenced
    (:func:`_precise_checks`)."""
    used = reg.get("georeferencing", {}).get("used", "gps")
    if used == "gps":
        return _gps_checks(reg, stable, change, offset, prior)
    return _precise_checks(reg, stable, diff) if used == "precise" else []


def _gps_checks(reg: dict, stable: np.ndarray, change: np.ndarray, offset: np.ndarray, prior: dict) -> list:
    """A registered run's checks: enough stable ground around the works, the pose within the
    georeferencing prior, the fit of the after survey."""
    return _stable_checks(stable, change, offset) + _prior_checks(reg, prior)


def _stable_checks(stable: np.ndarray, change: np.ndarray, offset: np.ndarray) -> list[tuple[str, str]]:
    """Enough stable ground, and around the works."""
    out: list[tuple[str, str]] = []
    valid = np.isfinite(offset)
    n_stable, n_valid = int(stable.sum()), max(int(valid.sum()), 1)
    if n_stable < MIN_STABLE_CELLS or n_stable / n_valid < MIN_STABLE_FRACTION:
        out.append(
            (
                "unreliable",
                f"too little stable ground ({n_stable / n_valid:.0%} of the compared area) to "
                "register the surveys and remove their bias: the works may have been absorbed",
            )
        )
    elif n_stable / n_valid < LOW_STABLE_FRACTION:
        out.append(
            (
                "caution",
                f"little stable ground ({n_stable / n_valid:.0%} of the compared area): the "
                "registration and bias correction rest on it alone; check that they did not absorb the works",
            )
        )
    elif largest_gap_deg(stable, change) > 180:
        out.append(
            (
                "caution",
                "the stable ground lies on one side of the works only: tilt and bias across the works are extrapolated",
            )
        )
    return out


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
            out.append(
                (
                    "caution",
                    f"the registration used {val:.2f} {unit} of a {limit:g} {unit} "
                    f"georeferencing prior ({key.split('_')[0]})",
                )
            )
    if reg.get("fine", {}).get("poses_beyond_prior", 0) > 0:  # registration's count, not its wording
        out.append(
            (
                "caution",
                "registration wanted a pose beyond the georeferencing prior (the works may "
                "pull it); the best pose within the prior was kept",
            )
        )
    fit = reg.get("fine", {}).get("fitness")
    if fit is not None and np.isfinite(fit) and fit < 0.5:
        out.append(("caution", f"only {fit:.0%} of the after survey fits the before surface after registration"))
    return out


def _precise_checks(reg: dict, stable: np.ndarray, diff: np.ndarray | None) -> list:
    """A run used as georeferenced: the ground outside the works agrees between the surveys,
    and, when auto chose it, the registration confirmed the coordinates."""
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
        out.append(
            (
                "caution",
                f"the ground outside the change areas differs by {shift:+.2f} m between the "
                "surveys and was not corrected (coordinates used as georeferenced): check the datums, or "
                f"use {opt('georeferencing', 'gps')} if it is a survey offset",
            )
        )
    return out
