"""The earthworks sections of report.html: bank, loose and compacted volumes (``quantities``), and
the progress against a design (``grade``)."""

from __future__ import annotations

from .text import Table, fmt, get, pm

KINDS = (("bank", "bank (measured)"), ("loose", "loose (bulking {f})"), ("compacted", "compacted (shrinkage {f})"))


def quantities(report: dict) -> Table | None:
    """The headline's net, cut and fill with their ± as bank, loose and compacted volumes (m³),
    each zone's below; None when the run gave no factor."""
    q = report.get("quantities")
    if not isinstance(q, dict):
        return None
    rows = _rows("", q)
    for z in get(report, "zones", default=[]) or []:
        if isinstance(z.get("quantities"), dict):
            rows += _rows(f"{z.get('name')}: ", z["quantities"])
    return Table(["", "net", "cut", "fill"], rows)


def _rows(prefix: str, q: dict) -> list[list[str]]:
    rows = []
    for key, text in KINDS:
        v = q.get(key)
        if isinstance(v, dict):
            half = v.get("interval_m3") or {}
            label = prefix + text.format(f=fmt(v.get("factor"), 2))
            rows.append([label] + [pm(v.get(k), half.get(k)) for k in ("net", "cut", "fill")])
    return rows


def grade(report: dict) -> Table | None:
    """Progress against the design (``grade``): the share on grade and the cut and fill still to
    go, overall and per zone; None without a tolerance."""
    g = report.get("grade")
    if not isinstance(g, dict):
        return None
    rows = [_grade_row("whole compared area", g)]
    rows += [_grade_row(str(z.get("name")), z) for z in g.get("zones") or []]
    head = [f"within ±{fmt(g.get('tolerance_m'), 3)} m", "on grade (%)", "cut to go (m³)", "fill to go (m³)"]
    return Table([*head, "compared area (m²)"], rows)


def _grade_row(label: str, g: dict) -> list[str]:
    share = g.get("on_grade_share")
    return [label, fmt(None if share is None else 100 * share, 1)] + [
        fmt(g.get(k), 1) for k in ("cut_to_go_m3", "fill_to_go_m3", "compared_area_m2")
    ]
