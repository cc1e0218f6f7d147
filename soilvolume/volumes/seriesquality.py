"""The quality verdict of each period of a series (and of the cumulative), in the words of a
pair's (:mod:`.quality`: reliable / use with caution / not reliable, with the reasons).

A period i -> j rests on two placements into E0's frame, Ei's and Ej's (E0 is the frame): each
later epoch's registration is judged as an estimate's is, on its pair E0 -> Ek (stable ground
around the works, the pose within the georeferencing prior, the fit; or, used as georeferenced,
the ground agreeing and the registration confirming the coordinates), and those reasons carry to
every period that epoch bounds. The period's own figures are then judged: the bias correction
of its two epochs over its change areas against its net, and whether the net is significant."""

from __future__ import annotations

import numpy as np

from .placement import registration_checks
from .quality import correction_check, significance_check, verdict


def epoch_checks(registrations: list[dict], vols: list, prior: dict) -> list[list[tuple[str, str]]]:
    """Each epoch's placement checks (E0's: none), worded with the epoch: ``registrations[k]``
    is report.json's ``epochs[k].registration``, ``vols[k - 1]`` the volume step of E0 -> Ek."""
    out: list[list[tuple[str, str]]] = [[]]
    for k, (reg, v) in enumerate(zip(registrations[1:], vols, strict=True), 1):
        found = registration_checks(reg, v.stable, v.change_mask, v.offset, prior, v.diff)
        out.append([(sev, f"E{k} in E0's frame: {said}") for sev, said in found])
    return out


def period_quality(change, checks: list[list[tuple[str, str]]], vols: list, cell_area: float) -> dict:
    """``{"verdict", "trusted", "messages"}`` of the period ``change`` (a
    :class:`~soilvolume.volumes.series.Change`), from its epochs' ``checks`` (:func:`epoch_checks`)
    and its own figures."""
    i, j = change.start, change.end
    found = (checks[i] if i else []) + checks[j]

    def offset(k: int) -> np.ndarray:
        return vols[k - 1].offset if k else np.zeros_like(vols[0].offset)

    areas = change.fill_area | change.cut_area
    corr = float(np.nansum(np.where(areas, offset(j) - offset(i), 0.0)) * cell_area)
    net, half = change.volume["net"], change.uncertainty["net"]
    return verdict(found + correction_check(corr, net, half) + significance_check(net, half))
