"""Earthworks quantities, overall and per zone: the measured (bank) volumes and intervals, ``loose =
bank * bulking`` (swell, e.g. 1.25: what a truck hauls) and ``compacted = bank * shrinkage`` (e.g.
0.90: once placed); a zone's own factors from its polygon's attributes (any case; empty: the run's)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..core.types import SoilVolumeError
from .polygons import feature_fields

#: the zones file's attributes that give a zone its own factors, and the option each overrides
FIELDS = ("bulking", "shrinkage")
PARTS = ("net", "cut", "fill")


def zone_factors(path: str | Path) -> dict[int, dict[str, float]]:
    """{feature id: {factor: value}} of the zones' set factors; one not a number > 0 an error naming file, zone,
    field."""
    out: dict[int, dict[str, float]] = {}
    for fid, props in feature_fields(path):
        lower = {str(k).lower(): v for k, v in props.items()}
        out[fid] = {}
        for name in FIELDS:
            value = lower.get(name)
            if value is None or (isinstance(value, float) and math.isnan(value)) or value == "":
                continue
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if not (math.isfinite(number) and number > 0):
                raise SoilVolumeError(f"{path}: feature {fid}: field '{name}' must be a number > 0 (got {value!r})")
            out[fid][name] = number
    return out


def scaled(volumes: dict[str, Any], half: dict[str, Any] | None, factors: dict[str, float]) -> dict[str, Any]:
    """``bank``, ``loose`` and ``compacted`` (for the factors given): net/cut/fill and ``interval_m3`` times the
    factor."""
    out = {"bank": _times(volumes, half, 1.0)}
    for key, name in (("loose", "bulking"), ("compacted", "shrinkage")):
        if factors.get(name) is not None:
            out[key] = {**_times(volumes, half, factors[name]), "factor": factors[name]}
    return out


def _times(volumes: dict[str, Any], half: dict[str, Any] | None, factor: float) -> dict[str, Any]:
    row = {k: volumes[k] * factor for k in PARTS}
    if half:
        row["interval_m3"] = {k: half[k] * factor for k in PARTS if half.get(k) is not None}
    return row


def quantities(report: dict, bulking: float | None, shrinkage: float | None, zones: str | None) -> dict | None:
    """report.json's ``quantities``, each zone row's set in ``report["zones"]``; None when no factor is given."""
    overall = {"bulking": bulking, "shrinkage": shrinkage}
    per_zone = zone_factors(zones) if zones else {}
    if bulking is None and shrinkage is None and not any(per_zone.values()):
        return None
    for row in report.get("zones") or []:
        own = {**overall, **per_zone.get(row["id"], {})}
        row["quantities"] = scaled(row, row.get("uncertainty_m3"), own)
    out = scaled(report["volume_m3"], report["uncertainty_m3"], overall)
    return {**out, "factors": overall}
