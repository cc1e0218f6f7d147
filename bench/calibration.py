"""Calibration harness (issue 53): default-option estimates over a population of random sites drawn
by ``bench/composer/``, scored against their exact truth.

    .venv/bin/python bench/calibration.py          # held-out population, 200 sites: bench/CALIBRATION.md
    .venv/bin/python bench/calibration.py --dev    # development population: bench/results/calibration-dev.md
    .venv/bin/python bench/calibration.py --quick  # first 20 held-out sites: bench/results/calibration-quick.md
    .venv/bin/python bench/calibration.py --seeds 90003,90007 --out /tmp/c.md

A number is *right* when the net is within 1 % and the cut and fill within 3 % of the true moved
volume (cut + fill; a floor of :data:`MIN_MOVED_M3` for sites with almost no works). Every site runs
``soilvolume.api.estimate(before, after, out, Options())`` and reads report.json's ``volume_m3``,
``uncertainty_m3`` (95 % half-widths) and ``quality.verdict``. Scenes, outputs and scored rows are
cached outside git in ``$SOILVOLUME_ACCURACY_CACHE`` or ``~/.cache/soilvolume-accuracy`` under
``calibration/`` (rows keyed by the composer's and the engine's source: a changed engine reruns);
the points of a scored site are deleted (they regenerate from the seed) unless ``--keep``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime, timezone
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

import accuracy  # noqa: E402
import calibration_report  # noqa: E402
import composer  # noqa: E402

from soilvolume.volumes.uncertainty import z_value  # noqa: E402

QUANTITIES = ("net", "cut", "fill")
LIMITS_PCT = {"net": 1.0, "cut": 3.0, "fill": 3.0}  # of the moved volume
MIN_MOVED_M3 = 10.0
N_HELD_OUT, N_DEV, N_QUICK = 200, 100, 20


def _digest(paths) -> str:
    h = hashlib.sha1()
    for p in sorted(paths):
        h.update(p.read_bytes())
    return h.hexdigest()[:10]


def code_keys() -> tuple[str, str]:
    """(scene key: the composer's and the scenes package's source, engine key: the rest of the
    engine's source)."""
    pkg = REPO / "soilvolume"
    scenes = list((pkg / "scenes").rglob("*.py")) + list((HERE / "composer").rglob("*.py"))
    engine = [p for p in pkg.rglob("*.py") if "scenes" not in p.relative_to(pkg).parts]
    return _digest(scenes), _digest(engine)


def judge(report: dict, truth: dict) -> dict:
    """Scored row: errors in m3 and in % of the moved volume, interval coverage, right or wrong."""
    row = accuracy.score(report, truth, None, False)
    moved = max(truth["cut"] + truth["fill"], MIN_MOVED_M3)
    row["moved_m3"] = truth["cut"] + truth["fill"]
    row["err_moved_pct"] = {q: 100.0 * row["err_m3"][q] / moved for q in QUANTITIES}
    row["badness"] = max(abs(row["err_moved_pct"][q]) / LIMITS_PCT[q] for q in QUANTITIES)
    row["right"] = row["badness"] <= 1.0
    quality = report.get("quality") or {}
    row["verdict"] = quality.get("verdict")
    row["messages"] = quality.get("messages", [])
    model = report.get("uncertainty") or {}
    z = z_value(model.get("confidence", 0.95))
    row["parts_m3"] = {q: [z * x for x in (model.get("terms_m3") or {}).get(q, [])] for q in QUANTITIES}
    row["bound_m3"] = {
        key: float(((report.get(key) or {}).get("bound_m3") or {}).get("net", 0.0)) for key in ("excluded", "blind")
    }
    return row


def run_site(seed: int, root: Path, keys: tuple[str, str], keep: bool = False) -> dict:
    """Compose, estimate and score site ``seed`` (cached by seed and source keys)."""
    cached = root / "rows" / f"s{seed}-{keys[0]}-{keys[1]}.json"
    if cached.exists():
        return json.loads(cached.read_text())
    desc = composer.draw_site(seed)
    base = {"seed": seed, "description": composer.describe(desc), "kinds": composer.kinds(desc)}
    scene = root / "scenes" / f"s{seed}-{keys[0]}"
    out = root / "runs" / f"s{seed}"
    try:
        if not all((scene / name).exists() for name in ("truth.json", "before.las", "after.las")):
            tmp = Path(tempfile.mkdtemp(prefix=".gen-", dir=root / "scenes"))
            composer.compose(seed, tmp)
            shutil.rmtree(scene, ignore_errors=True)
            tmp.rename(scene)
        truth = json.loads((scene / "truth.json").read_text())
        report, wall = accuracy.run_estimate(scene / "before.las", scene / "after.las", out, {})
        row = {**base, **judge(report, truth), "wall_s": wall}
    except Exception as exc:  # one failing site must not stop the population
        row = {**base, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(limit=3)}
    if not keep:
        shutil.rmtree(out, ignore_errors=True)
        for name in ("before.las", "after.las"):
            (scene / name).unlink(missing_ok=True)
    if not row.get("error"):  # a failed site is tried again next time
        cached.write_text(json.dumps(row, default=str) + "\n")
    return row


def _line(i: int, n: int, row: dict) -> str:
    if row.get("error"):
        return f"[calibration] {i}/{n} s{row['seed']} ERROR {row['error']}"
    e = row["err_moved_pct"]
    cov = "".join("y" if row["covered"][q] else "n" for q in QUANTITIES)
    return (
        f"[calibration] {i}/{n} s{row['seed']} net {e['net']:+.2f} cut {e['cut']:+.2f} fill {e['fill']:+.2f} "
        f"% of moved, in95 {cov}, {'right' if row['right'] else 'WRONG'}, {row['verdict']}"
    )


def run_population(seeds: list[int], root: Path, jobs: int = 1, keep: bool = False) -> list[dict]:
    """Scored rows of every seed (in seed order), ``jobs`` sites at a time."""
    for d in ("rows", "scenes", "runs"):
        (root / d).mkdir(parents=True, exist_ok=True)
    keys = code_keys()
    rows = []
    if jobs <= 1:
        for i, seed in enumerate(seeds, 1):
            rows.append(run_site(seed, root, keys, keep))
            print(_line(i, len(seeds), rows[-1]), flush=True)
        return rows
    with ProcessPoolExecutor(jobs) as pool:
        futures = [pool.submit(run_site, s, root, keys, keep) for s in seeds]
        for i, f in enumerate(futures, 1):
            rows.append(f.result())
            print(_line(i, len(seeds), rows[-1]), flush=True)
    return rows


def _commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        return out.stdout.strip() or "?"
    except OSError:
        return "?"


def population(args) -> tuple[str, list[int], Path]:
    """(name, seeds, default report path) of the run the arguments ask for."""
    if args.seeds:
        return "chosen seeds", [int(s) for s in args.seeds.split(",")], HERE / "results" / "calibration-seeds.md"
    if args.dev:
        seeds = list(composer.DEV_SEEDS[: args.n or N_DEV])
        return "development", seeds, HERE / "results" / "calibration-dev.md"
    if args.quick:
        return "held-out (quick)", list(composer.HELD_OUT_SEEDS[:N_QUICK]), HERE / "results" / "calibration-quick.md"
    n = args.n or N_HELD_OUT
    out = HERE / "CALIBRATION.md" if n >= N_HELD_OUT else HERE / "results" / f"calibration-{n}.md"
    return "held-out", list(composer.HELD_OUT_SEEDS[:n]), out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dev", action="store_true", help="the development population")
    ap.add_argument("--quick", action="store_true", help=f"the first {N_QUICK} held-out sites")
    ap.add_argument("--n", type=int, help="number of sites (default: held-out 200, dev 100)")
    ap.add_argument("--seeds", help="comma-separated seeds instead of a population")
    ap.add_argument("--jobs", type=int, default=1, help="sites at a time (default 1)")
    ap.add_argument("--out", type=Path, help="markdown report (default by population)")
    ap.add_argument("--cache", type=Path, help="cache folder (default ~/.cache/soilvolume-accuracy)")
    ap.add_argument("--keep", action="store_true", help="keep the points and outputs of scored sites")
    args = ap.parse_args(argv)
    name, seeds, default_out = population(args)
    root = (args.cache or accuracy.cache_root()) / "calibration"
    t0, commit = time.perf_counter(), _commit()
    rows = run_population(seeds, root, args.jobs, args.keep)
    meta = {
        "population": name,
        "seeds": f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 2 else ",".join(map(str, seeds)),
        "n": len(seeds),
        "commit": commit,
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "minutes": (time.perf_counter() - t0) / 60.0,
        "argv": " ".join(argv if argv is not None else sys.argv[1:]),
    }
    out = args.out or default_out
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(calibration_report.markdown(rows, meta))
    raw = out.with_suffix(".json") if out.parent != HERE else HERE / "results" / "calibration-latest.json"
    raw.parent.mkdir(parents=True, exist_ok=True)
    raw.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=str) + "\n")
    print(f"[calibration] wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
