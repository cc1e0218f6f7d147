"""What a composed site's error comes from (issue 53): the site rerun with one of its conditions
taken away (what is not soil, the georeferencing error, doming and strays, partial coverage and
holes, a second kind of sensor); the condition whose removal takes the error away is its cause.

    .venv/bin/python bench/calibration_attribution.py --from bench/results/calibration-latest.json --worst 40
"""

from __future__ import annotations

import argparse
import copy
import json
import shutil
import sys
import tempfile
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import accuracy  # noqa: E402
import calibration  # noqa: E402
import composer  # noqa: E402


def _no_objects(d: dict) -> bool:
    changed = bool(d["objects"])
    d["objects"] = []
    return changed


def _precise(d: dict) -> bool:
    changed = d["georef"]["kind"] != "precise"
    d["georef"] = {"kind": "precise", "shift_m": [0.0] * 3, "rotation_deg": [0.0] * 3, "strips": None}
    d["georef"]["vertical_datum"] = None
    return changed


def _no_doming(d: dict) -> bool:
    changed = any(s["doming_m"] or s["outliers"] for s in d["sensors"])
    for s in d["sensors"]:
        s["doming_m"], s["outliers"] = 0.0, 0.0
    return changed


def _covered(d: dict) -> bool:
    changed = d["coverage"]["overlap"] < 1.0 or any(d["coverage"]["holes"])
    d["coverage"] = {"overlap": 1.0, "holes": [0, 0]}
    return changed


def _one_sensor(d: dict) -> bool:
    before, after = d["sensors"]
    if before["kind"] == after["kind"]:
        return False
    d["sensors"][0] = dict(after, epoch="before", density=before["density"], doming_m=0.0)
    return True


VARIANTS = {
    "not soil": _no_objects,
    "georeferencing": _precise,
    "doming, strays": _no_doming,
    "coverage": _covered,
    "mixed sensors": _one_sensor,
}


def variant_row(seed: int, name: str, root: Path) -> dict | None:
    """The scored row of site ``seed`` without the condition ``name`` (None: the site has none)."""
    desc = copy.deepcopy(composer.draw_site(seed))
    if not VARIANTS[name](desc):
        return None
    work = Path(tempfile.mkdtemp(prefix=f"s{seed}-", dir=root))
    try:
        before, after, truth = composer.write_site(composer.Site(desc), work / "scene")
        report, _ = accuracy.run_estimate(before, after, work / "out", {})
        return calibration.judge(report, json.loads(truth.read_text()))
    finally:
        shutil.rmtree(work, ignore_errors=True)


def attribute(row: dict, variants: dict[str, dict | None]) -> str:
    """The condition whose removal cuts the net error most (at least by half), else "several"."""
    err = abs(row["err_m3"]["net"]) + abs(row["err_m3"]["cut"]) + abs(row["err_m3"]["fill"])
    best, best_err = "several or the works", err
    for name, v in variants.items():
        if v is None:
            continue
        e = abs(v["err_m3"]["net"]) + abs(v["err_m3"]["cut"]) + abs(v["err_m3"]["fill"])
        if e < best_err and (e <= 0.5 * err or v["right"]):
            best, best_err = name, e
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--from", dest="source", type=Path, required=True, help="a calibration JSON")
    ap.add_argument("--worst", type=int, default=40, help="the wrong sites to attribute, worst first")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=HERE / "results" / "calibration-attribution.json")
    args = ap.parse_args(argv)
    rows = [r for r in json.loads(args.source.read_text())["rows"] if not r.get("error") and not r["right"]]
    rows = sorted(rows, key=lambda r: -r["badness"])[: args.worst]
    root = Path(tempfile.mkdtemp(prefix="attribution-"))
    jobs = [(r["seed"], name) for r in rows for name in VARIANTS]
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(variant_row, *zip(*jobs, strict=True), [root] * len(jobs)))
    shutil.rmtree(root, ignore_errors=True)
    out, causes = [], Counter()
    for i, r in enumerate(rows):
        variants = dict(zip(VARIANTS, results[i * len(VARIANTS) : (i + 1) * len(VARIANTS)], strict=True))
        cause = attribute(r, variants)
        causes[cause] += 1
        out.append({"seed": r["seed"], "cause": cause, "row": r, "variants": variants})
        print(f"s{r['seed']} net {r['err_m3']['net']:+.0f} m3 -> {cause}: {r['description'][:160]}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"causes": dict(causes), "sites": out}, indent=1, default=str) + "\n")
    print(dict(causes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
