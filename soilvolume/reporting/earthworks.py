"""The earthworks sections of report.html: bank, loose and compacted volumes (``quantities``)."""

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
