"""The paper pair (or its 50 m LAS tiles on ``--scheduler local:2``) run by several checkouts of the
project, interleaved round by round: wall time, CPU, peak RSS and the stage timings of report.json.

    .venv/bin/python bench/trees.py /path/to/checkout-a /path/to/checkout-b --rounds 10
    .venv/bin/python bench/trees.py A B --tiles

Each checkout needs its own ``.venv`` (or a link to one) and is put first on ``PYTHONPATH``, so a
worktree at an older commit (``git worktree add ../old 01d627d``) runs its own code. Bytecode is
written as usual (a checkout that recompiled every module each run would look ~0.1 s slower). The
pair is the cached one of ``run_bench.py`` (generated once). Medians are printed, with the paired
median ratio of each checkout to the first.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from run_bench import cache_root, ensure_scene, ensure_tiles  # noqa: E402


def inputs(tiles: bool) -> list[str]:
    """The paper pair's files, or its tiles and the local cluster."""
    before, after, _, _ = ensure_scene("paper", 0, "las", cache_root())
    if not tiles:
        return [str(before), str(after)]
    return [str(ensure_tiles(before, 50.0)), str(ensure_tiles(after, 50.0)), "--scheduler", "local:2"]


def run_once(tree: Path, args: list[str], out: Path) -> dict:
    """One estimate by ``tree``'s code: wall, CPU (user + sys), peak RSS (MB), stage timings."""
    shutil.rmtree(out, ignore_errors=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        argv = ["/usr/bin/time", "-f", "%M %U %S", "-o", tf.name, str(tree / ".venv/bin/soilvolume"), "estimate"]
        t = time.perf_counter()
        r = subprocess.run([*argv, *args, "--out", str(out)], capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t
        if r.returncode:
            raise SystemExit(f"{tree}: the estimate failed: {r.stderr.strip()[-400:]}")
        rss, user, system = tf.read().split()[-3:]
    stages = json.loads((out / "report.json").read_text()).get("timings_s", {})
    return {"wall": wall, "cpu": float(user) + float(system), "rss": int(rss) / 1024, "stages": stages}


def summary(runs: list[dict], first: list[dict]) -> str:
    """Medians of one checkout's runs and its paired ratio to the first checkout's."""
    med = statistics.median
    ratio = med(b["wall"] / a["wall"] for a, b in zip(first, runs, strict=True))
    stages = {k: round(med(r["stages"].get(k, 0.0) for r in runs), 3) for k in runs[0]["stages"]}
    return (
        f"wall {med(r['wall'] for r in runs):.3f} s (x{ratio:.3f})  cpu {med(r['cpu'] for r in runs):.2f} s  "
        f"rss {med(r['rss'] for r in runs):.0f} MB\n    {stages}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trees", nargs="+", type=Path, help="checkouts of the project, each with its .venv")
    ap.add_argument("--rounds", type=int, default=10, help="interleaved rounds (default 10)")
    ap.add_argument("--tiles", action="store_true", help="the pair as 50 m LAS tiles on --scheduler local:2")
    args = ap.parse_args(argv)
    trees = [t.resolve() for t in args.trees]
    files = inputs(args.tiles)
    runs: dict[Path, list[dict]] = {t: [] for t in trees}
    with tempfile.TemporaryDirectory(prefix="trees-") as tmp:
        for _ in range(args.rounds):
            for k, tree in enumerate(trees):
                runs[tree].append(run_once(tree, files, Path(tmp) / str(k)))
    for tree in trees:
        print(f"{tree}: {summary(runs[tree], runs[trees[0]])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
