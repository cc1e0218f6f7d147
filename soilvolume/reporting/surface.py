"""report.html's wording of a run against a reference surface (a design or an earlier DEM):
volumes above and below the design, and the reference in place of the registration."""

from __future__ import annotations

from ..compensation.stable import find_stable
from ..volumes import reference
from .text import Table

NONE = "none: the reference is a surface"  # report.json's registration.kind of such a run
WORDING = {"fill": "above design", "cut": "below design", "net": "above minus below design"}
METHOD = (
    "the survey against the reference surface (resampled onto the survey's grid): fill = the survey above the "
    "design, cut = below it, over the survey's footprint clipped to the design's valid extent; "
)


def is_surface(report: dict) -> bool:
    """Whether the run's reference is a surface (report.json's ``reference.kind``)."""
    return (report.get("reference") or {}).get("kind") == "surface"


def amend(report: dict, prep, vols) -> dict:
    """report.json of a run against a surface (``prep.inputs["before"]`` describes it):
    ``reference``, the registration's kind, the volumes' wording; others returned as they are."""
    ref = (prep.inputs or {}).get("before") or {}
    if ref.get("kind") != "surface":
        return report
    report["registration"]["kind"] = NONE
    report["reference"] = {**ref, "wording": WORDING, "uncertainty_m3": vols.uncertainty.get("reference_m3")}
    report["volume_method"] = METHOD + report["volume_method"]
    return report


def surface_quality(report: dict, record) -> dict:
    """The verdict against a surface (``record``: a RunRecord): the survey's agreement with it on the
    cells deemed unchanged (``reference.agreement``) first."""
    diff = record.quality.diff
    unchanged = find_stable(diff, record.grid.cell)[0]
    agree = reference.agreement(diff, unchanged, record.vols.uncertainty["lod_m"], record.grid.cell_area)
    found = reference.check(agree)
    report["reference"]["agreement"] = {**agree, "agrees": not found[0]}  # its sentence is then no warning
    return reference.merge(report["quality"], found)


def words(report: dict) -> tuple[str, str, str]:
    """(the headline's lead, the cut's word, the fill's word)."""
    if is_surface(report):
        return "Survey against the design: net", "below design", "above design"
    return "Net change", "cut", "fill"


def section(report: dict) -> Table:
    """The reference surface and the survey's agreement with it on unchanged ground."""
    ref = report.get("reference") or {}
    agree = ref.get("agreement") or {}

    def fmt(value, digits=3):
        return "n/a" if not isinstance(value, (int, float)) else f"{value:,.{digits}f}"

    rows = [
        ["surface", str(ref.get("path", ""))],
        ["CRS", str(ref.get("crs", ""))],
        ["resolution (m)", fmt(ref.get("resolution_m"))],
        ["heights' unit from", str(ref.get("vertical_unit", ""))],
        ["unchanged ground compared (m²)", fmt(agree.get("area_m2"), 0)],
        ["median survey − design there (m)", fmt(agree.get("median_m"))],
        ["NMAD there (m)", fmt(agree.get("nmad_m"))],
        ["level of detection (m)", fmt(agree.get("lod_m"))],
    ]
    return Table(["", "value"], rows)
