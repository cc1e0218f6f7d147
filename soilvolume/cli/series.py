"""``soilvolume series E0 E1 ... --out DIR``: volume change over a series of surveys."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..reporting.serieshtml import changes
from ..workflow.series import run_series
from .flags import add_options, add_progress, hooks, options_from, result

NAME = "series"

EPILOG = """Outputs in DIR: dem_epoch<k>.tif (each epoch's heights in E0's frame, corrected
once relative to E0; dem_epoch<j> - dem_epoch<i> = difference_<i>_<j>), difference_<i>_<j>.tif
(each period's change), cumulative_0_<n>.tif,
ledger.csv (one row per period and the cumulative: epochs, dates, net/cut/fill and their ±),
report.json ("epochs" with each registration's 4x4 into E0's frame, "periods", "cumulative", each
with its quality verdict) and report.html (the ledger with the verdicts, cumulative cut and fill
over time, the difference maps). The periods'
nets add up to the cumulative net. --before-crs applies to E0, --after-crs to every later epoch.
With --design DESIGN.tif|.xml --tolerance T (and --zones): grade_epoch<k>.tif, each epoch's share on
grade and cut and fill still to go against the design, each period's cut and fill done (report.json's
"grade" and "progress", the ledger's last columns, report.html).
The outputs appear together or not at all; exit status 0 (done), 1 (error, one line on stderr),
2 (bad command line), 130/143 (interrupted; nothing written)."""


def add_parser(sub) -> None:
    """The sub-command: epochs, --out, --dates, --overwrite, and its options."""
    p = sub.add_parser(
        NAME,
        help="volume change over a series of surveys E0 E1 ... (E0 the reference)",
        description="Register every later survey into E0's frame, grid all on one grid and report each "
        "period's volume change (consecutive surveys) and the cumulative one, with intervals.",
        epilog=EPILOG,
    )
    p.add_argument(
        "epochs",
        type=Path,
        nargs="+",
        help="the surveys in time order, E0 first (the formats of estimate); refused when their dates "
        "(--dates, else the LAS headers') are out of that order",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder (created; must be empty unless --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace the output folder of an earlier run as a whole")
    p.add_argument(
        "--dates",
        help="the surveys' dates, comma-separated YYYY-MM-DD, one per epoch (an empty entry keeps the "
        "file's; default: each LAS header's creation day and year)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress output")
    add_progress(p)
    add_options(p, NAME)


def run(ns: argparse.Namespace) -> int:
    """Run the series; print the ledger (or send the result through the protocol)."""
    dates = None if ns.dates is None else ns.dates.split(",")
    res = run_series(ns.epochs, ns.out, options_from(ns), dates=dates, overwrite=ns.overwrite, hooks=hooks(ns))
    data = {"report": res.report, "outputs": res.outputs}
    return result(ns, data, [*ledger_lines(res.report), f"outputs in {ns.out}"])


def ledger_lines(report: dict) -> list[str]:
    """The ledger in words: one line per period and the cumulative, each with its quality
    verdict and reasons."""
    lines = []
    for name, p in changes(report):
        v, u = p["volume_m3"], p["uncertainty_m3"]
        when = " -> ".join(d or "?" for d in p["dates"])
        name = name if name == "cumulative" else f"period {name}"
        lines.append(
            f"{name} E{p['from']} -> E{p['to']} ({when}): net {v['net']:+.2f} ± {u['net']:.2f} m3  "
            f"cut {v['cut']:.2f} ± {u['cut']:.2f}  fill {v['fill']:.2f} ± {u['fill']:.2f}"
        )
        if q := p.get("quality"):
            lines += [f"  quality: {q['verdict'].upper()}"] + [f"    - {m}" for m in q["messages"]]
    return lines
