"""A series against a design in its outputs: grade_epoch<k>.tif, report.json's ``design``, each
epoch's ``grade``, each period's ``progress``, the ledger's columns and report.html's table."""

from __future__ import annotations

from ..core.types import GridSpec
from ..dem.geotiff import write_grid
from ..volumes.grade import progress
from .text import Table, fmt

#: the ledger's columns with a design: the grade at the period's end and the progress over it
LEDGER_GRADE = ("on_grade_share", "cut_to_go_m3", "fill_to_go_m3", "cut_done_m3", "fill_done_m3")


GRADE_FILES = "grade_epoch<k>.tif"


def grade_name(k: int) -> str:
    return f"grade_epoch{k}.tif"


def write_grades(out, graded, grid: GridSpec) -> None:
    """Each epoch's class grid against the design (uint8: 1 cut to go, 2 on grade, 3 fill to go, 255 not compared)."""
    said = f"1 cut to go, 2 on grade (within {graded.tolerance:g} m of the design), 3 fill to go"
    for k, cls in enumerate(graded.classes):
        write_grid(out.path(grade_name(k)), cls, grid, f"epoch {k}: {said}", units="", dtype="uint8")


def with_grade(report: dict, graded) -> dict:
    """``report`` with the design, each epoch's ``grade`` and each period's and the cumulative's
    ``progress`` (:func:`~soilvolume.workflow.seriesgrade.progress`); as it is without a design."""
    if graded is None:
        return report
    report["design"] = {
        "path": graded.design,
        "tolerance_m": graded.tolerance,
        "zones": graded.zones,
        "grades": GRADE_FILES,
    }
    for e, g in zip(report["epochs"], graded.grades, strict=True):
        e["grade"] = g
    grades = graded.grades
    for p in [*report["periods"], report["cumulative"]]:
        p["progress"] = progress(grades[p["from"]], grades[p["to"]])
    return report


def ledger_figures(p: dict) -> list[str]:
    """A ledger row's grade columns (:data:`LEDGER_GRADE`) of a period or the cumulative."""
    g = p["progress"]
    share = g["on_grade_share"]
    return ["" if share is None else f"{share:.6f}"] + [f"{g[k] + 0.0:.3f}" for k in LEDGER_GRADE[1:]]  # no -0.000


def progress_table(report: dict) -> Table | None:
    """report.html's progress against the design: each epoch's share on grade and its cut and
    fill to go, each period's cut and fill done; None without a design."""
    design = report.get("design")
    if not design:
        return None
    rows = []
    for e in report["epochs"]:
        g = e["grade"]
        share = g["on_grade_share"]
        rows.append([f"E{e['index']}", fmt(None if share is None else 100 * share, 1)] + _to_go(g) + ["", ""])
    for k, p in enumerate(report["periods"]):
        g = p["progress"]
        done = [fmt(g["cut_done_m3"], 1), fmt(g["fill_done_m3"], 1)]
        rows.append([f"period {k + 1} (E{p['from']} → E{p['to']})", "", "", "", *done])
    head = ["", f"on grade, ±{fmt(design['tolerance_m'], 3)} m (%)", "cut to go (m³)", "fill to go (m³)"]
    return Table([*head, "cut done (m³)", "fill done (m³)"], rows)


def _to_go(g: dict) -> list[str]:
    return [fmt(g["cut_to_go_m3"] + 0.0, 1), fmt(g["fill_to_go_m3"] + 0.0, 1)]  # no -0.0
