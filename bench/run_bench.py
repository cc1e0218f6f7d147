"""Benchmark harness (issue 5): time, peak memory and volume error of whole CLI runs.

    .venv/bin/python bench/run_bench.py                 # paper, 1M, 4M
    .venv/bin/python bench/run_bench.py --full          # + 16M and 64M
    .venv/bin/python bench/run_bench.py --sizes paper --repeat 3
    .venv/bin/python bench/run_bench.py --cmd \
        "{python} {repo}/bench/standin_cli.py estimate {before} {after} --out {out} --overwrite"

For every scene it (1) generates the seeded synthetic pair once (streamed, cached outside git in
``$SOILVOLUME_BENCH_CACHE`` or ``~/.cache/soilvolume-bench``), (2) runs the estimate command as
its own process under ``/usr/bin/time -v`` (or a ``resource`` wrapper) for wall time and peak RSS,
(3) runs the I/O floor (``bench/floor.py``: read both files, write three GeoTIFFs of the same grid)
as another process, and (4) compares ``report.json``'s ``volume_m3.net`` with ``truth.json``.
Writes ``bench/results/latest.json`` and ``bench/results/latest.png`` and prints a table
(``--update-readme`` also rewrites the table in ``bench/README.md``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

from memory import TreeSampler  # noqa: E402
from tiles import split  # noqa: E402

from soilvolume.scenes import synthetic  # noqa: E402
from soilvolume.scenes.synthetic import SceneConfig  # noqa: E402

STAGES = ["read", "crop", "coarse", "fine", "planes", "grids", "volume", "write"]
LADDER = {"1M": 1_000_000, "4M": 4_000_000, "16M": 16_000_000, "64M": 64_000_000}
DEFAULT_SIZES = "paper,1M,4M"
FULL_SIZES = "paper,1M,4M,16M,64M"
DEFAULT_CMD = "{venv}/bin/soilvolume estimate {before} {after} --out {out} --overwrite"
README_START = "<!-- bench:latest:start -->"
README_END = "<!-- bench:latest:end -->"

# resource-based fallback when /usr/bin/time is missing: run argv, report the child's peak RSS
_WRAP = (
    "import json,resource,subprocess,sys,time;t=time.perf_counter();"
    "rc=subprocess.call(sys.argv[2:]);w=time.perf_counter()-t;"
    "r=resource.getrusage(resource.RUSAGE_CHILDREN);"
    "open(sys.argv[1],'w').write(json.dumps({'rc':rc,'wall':w,'maxrss_kb':r.ru_maxrss}))"
)


def scene_config(name: str) -> SceneConfig:
    if name == "paper":
        return SceneConfig.paper()
    if name in LADDER:
        return SceneConfig.paper().with_total_points(LADDER[name])
    m = re.fullmatch(r"(\d+(?:\.\d+)?)([kKmM])", name)
    if m:
        n = float(m.group(1)) * (1e3 if m.group(2) in "kK" else 1e6)
        return SceneConfig.paper().with_total_points(int(n))
    raise SystemExit(f"unknown scene {name!r}: use paper, 1M, 4M, 16M, 64M or e.g. 250k, 8M")


def cache_root() -> Path:
    env = os.environ.get("SOILVOLUME_BENCH_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "soilvolume-bench"


def ensure_scene(name: str, seed: int, fmt: str, root: Path) -> tuple[Path, Path, Path, float]:
    """Generate (once) the scene's files; returns before, after, truth paths and the seconds
    spent generating (0 when cached). The cache key covers the config and the generator code."""
    cfg = scene_config(name)
    src = b"".join(p.read_bytes() for p in sorted(Path(synthetic.__file__).parent.glob("*.py")))  # scenes/
    key = hashlib.sha1(json.dumps(asdict(cfg), sort_keys=True).encode() + src + fmt.encode()).hexdigest()[:10]
    d = root / f"pair-{cfg.before_points + cfg.after_points}-s{seed}-{key}"
    files = (d / f"before.{fmt}", d / f"after.{fmt}", d / "truth.json")
    if all(f.exists() for f in files):
        return (*files, 0.0)
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=root))
    t = time.perf_counter()
    print(f"[bench] generating {name} ({cfg.before_points:,} + {cfg.after_points:,} points) in {d} ...", flush=True)
    synthetic.write_pair_streaming(seed, cfg, tmp, fmt=fmt)
    if d.exists():
        shutil.rmtree(d)
    tmp.rename(d)
    return (*files, time.perf_counter() - t)


def warm(paths) -> None:
    """Read the files once so every timed process sees the same (warm) page cache."""
    for p in paths:
        with open(p, "rb") as f:
            while f.read(1 << 24):
                pass


def timed(argv: list[str], timeout: float, log: Path) -> dict:
    """Run argv; return rc, wall seconds, peak RSS (MB) of the process, tail of stderr."""
    with tempfile.NamedTemporaryFile("r", suffix=".time", delete=False) as tf:
        tpath = tf.name
    gnu_time = Path("/usr/bin/time")
    if gnu_time.exists():
        full = [str(gnu_time), "-v", "-o", tpath, *argv]
    else:
        full = [sys.executable, "-c", _WRAP, tpath, *argv]
    t = time.perf_counter()
    with open(log, "w") as lf:
        proc = subprocess.Popen(full, stdout=lf, stderr=subprocess.STDOUT)
        with TreeSampler(proc.pid) as tree:
            try:
                rc = proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                rc = "timeout"
    wall = time.perf_counter() - t
    per_process = sorted(
        (
            (round(mb), name)
            for pid, (mb, name) in tree.peaks.items()
            if name not in ("time", "python3") or pid != proc.pid
        ),
        reverse=True,
    )
    peak_mb = None
    text = Path(tpath).read_text() if Path(tpath).exists() else ""
    os.unlink(tpath)
    if gnu_time.exists():
        m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", text)
        peak_mb = int(m.group(1)) / 1024.0 if m else None
        m = re.search(r"Exit status: (\d+)", text)
        if m and rc != "timeout":
            rc = int(m.group(1))
    elif text:
        info = json.loads(text)
        peak_mb, rc = info["maxrss_kb"] / 1024.0, info["rc"]
    tail = log.read_text(errors="replace").strip().splitlines()[-15:] if log.exists() else []
    largest = max((mb for mb, name in per_process if name != "time"), default=None)
    return {
        "rc": rc,
        "wall_s": wall,
        "peak_rss_mb": peak_mb,
        "largest_process_mb": largest,
        "processes_sum_mb": round(tree.total),
        "processes": per_process[:8],
        "log_tail": tail,
    }


def las_count(path: Path) -> int:
    from soilvolume.inputs.stream import open_source

    return int(open_source(path).count)


def files(path: Path) -> list[Path]:
    """The files behind an input (a VPC's tiles)."""
    if path.suffix != ".vpc":
        return [path]
    from soilvolume.inputs.vpc import read_vpc

    return [Path(t.path) for t in read_vpc(path).tiles]


def ensure_tiles(path: Path, tile_m: float) -> Path:
    """``path`` split once into LAZ tiles of ``tile_m`` metres + a VPC (cached beside it)."""
    folder = path.parent / f"tiles-{tile_m:g}m"
    vpc = folder / f"{path.stem}.vpc"
    if not vpc.exists():
        print(f"[bench] tiling {path} into {tile_m:g} m LAZ tiles ...", flush=True)
        tmp = Path(tempfile.mkdtemp(prefix=".tiles-", dir=path.parent))
        split(path, tmp, tile_m)
        folder.mkdir(exist_ok=True)
        for f in tmp.iterdir():
            os.replace(f, folder / f.name)
        tmp.rmdir()
    return vpc


def run_scene(name: str, args, root: Path, runs: Path, scheduler: str = "") -> dict:
    before, after, truth_path, gen_s = ensure_scene(name, args.seed, args.fmt, root)
    originals = (before, after)
    if args.layout == "vpc":
        before, after = ensure_tiles(before, args.tile_m), ensure_tiles(after, args.tile_m)
    truth = json.loads(truth_path.read_text())
    nb, na = las_count(before), las_count(after)
    inputs = files(before) + files(after)
    warm(inputs)
    label = name + (f" [{scheduler}]" if scheduler else "") + (" vpc" if args.layout == "vpc" else "")
    out = runs / re.sub(r"[^\w.-]+", "_", label)
    venv = Path(args.venv)
    fmt_args = {
        "before": shlex.quote(str(before)),
        "after": shlex.quote(str(after)),
        "out": shlex.quote(str(out)),
        "venv": shlex.quote(str(venv)),
        "python": shlex.quote(str(venv / "bin" / "python")),
        "repo": shlex.quote(str(REPO)),
    }
    argv = shlex.split(args.cmd.format(**fmt_args)) + (["--scheduler", scheduler] if scheduler else [])
    res: dict = {
        "scene": name,
        "label": label,
        "scheduler": scheduler or "default",
        "layout": args.layout,
        "tiles": len(inputs),
        "points_before": nb,
        "points_after": na,
        "points": nb + na,
        "files_mb": round(sum(f.stat().st_size for f in inputs) / 2**20, 1),
        "generate_s": round(gen_s, 2),
        "truth_net_m3": truth["net"],
        "truth_cut_m3": truth["cut"],
        "truth_fill_m3": truth["fill"],
        "runs": [],
    }
    best = None
    for i in range(args.repeat):
        if out.exists():
            shutil.rmtree(out)
        print(f"[bench] {name}: run {i + 1}/{args.repeat}: {' '.join(argv)}", flush=True)
        r = timed(argv, args.timeout, runs / f"{out.name}.log")
        rep_path = out / "report.json"
        report = json.loads(rep_path.read_text()) if rep_path.exists() and r["rc"] == 0 else None
        r["report"] = report
        res["runs"].append({k: v for k, v in r.items() if k not in ("report", "log_tail")})
        if r["rc"] != 0 or report is None:
            res["error"] = f"exit {r['rc']}" + ("" if report else ", no report.json")
            res["log_tail"] = r["log_tail"]
            print(f"[bench] {name}: FAILED ({res['error']})\n    " + "\n    ".join(r["log_tail"]), flush=True)
            break
        if best is None or r["wall_s"] < best["wall_s"]:
            best = r
    if best is not None:
        report = best["report"]
        res["wall_s"] = best["wall_s"]
        res["peak_rss_mb"] = best["peak_rss_mb"]
        for k in ("largest_process_mb", "processes_sum_mb", "processes"):
            res[k] = best.get(k)
        res["timings_s"] = report.get("timings_s", {})
        vol = report.get("volume_m3", {}) or {}
        res["net_m3"] = vol.get("net")
        res["cut_m3"] = vol.get("cut")
        res["fill_m3"] = vol.get("fill")
        if res["net_m3"] is not None and truth["net"]:
            res["net_error_pct"] = 100.0 * (res["net_m3"] - truth["net"]) / abs(truth["net"])
        grid = report.get("grid", {}) or {}
        res["grid"] = {k: grid.get(k) for k in ("cell_m", "rows", "cols") if k in grid}
        shutil.copy(out / "report.json", runs / f"{out.name}.report.json")
        if not args.keep_outputs:
            shutil.rmtree(out, ignore_errors=True)

    # the floor: read both files + write three GeoTIFFs of the same grid, own process
    fl_out = runs / f"{out.name}-floor"
    fl_argv = [str(venv / "bin" / "python"), str(HERE / "floor.py"), str(originals[0]), str(originals[1]), str(fl_out)]
    cell = (res.get("grid") or {}).get("cell_m")
    if cell:
        fl_argv += ["--cell", str(cell)]
    fl_best = None
    for _ in range(args.repeat):
        r = timed(fl_argv, args.timeout, runs / f"{out.name}-floor.log")
        if r["rc"] != 0:
            res["floor_error"] = f"exit {r['rc']}: " + " | ".join(r["log_tail"][-3:])
            break
        if fl_best is None or r["wall_s"] < fl_best["wall_s"]:
            fl_best = r
    shutil.rmtree(fl_out, ignore_errors=True)
    if fl_best is not None:
        res["floor_wall_s"] = fl_best["wall_s"]
        res["floor_peak_rss_mb"] = fl_best["peak_rss_mb"]
        if res.get("wall_s"):
            res["ratio_to_floor"] = res["wall_s"] / fl_best["wall_s"]
    return res


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gb = None
    try:
        m = re.search(r"MemTotal:\s+(\d+)", Path("/proc/meminfo").read_text())
        mem_gb = round(int(m.group(1)) / 2**20, 1) if m else None
    except OSError:
        pass

    def git(*a: str) -> str:
        try:
            return subprocess.run(["git", *a], cwd=REPO, capture_output=True, text=True, timeout=20).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "mem_gb": mem_gb,
        "os": platform.platform(),
        "python": platform.python_version(),
        "git_commit": git("rev-parse", "--short", "HEAD"),
        "git_dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
    }


def _f(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def table(results: list[dict]) -> str:
    extra = []
    for r in results:
        for k in r.get("timings_s", {}):
            if k not in STAGES and k not in extra:
                extra.append(k)
    stages = STAGES + extra
    head = (
        ["scene", "points", "scheduler"]
        + stages
        + ["wall s", "peak MB", "largest process MB", "all processes MB", "floor s", "x floor", "net err %", "load"]
    )
    rows = []
    for r in results:
        t = r.get("timings_s", {})
        name = r["scene"] + (f" (= {r['same_as']})" if r.get("same_as") else "")
        if r.get("layout") == "vpc":
            name += f" (VPC, {r['tiles']} tiles)"
        rows.append(
            [name, f"{r['points'] / 1e6:.2f}M", r.get("scheduler", "default")]
            + [_f(t.get(s), ".2f") for s in stages]
            + [
                _f(r.get("wall_s"), ".2f"),
                _f(r.get("peak_rss_mb"), ".0f"),
                _f(r.get("largest_process_mb"), ".0f"),
                _f(r.get("processes_sum_mb"), ".0f"),
                _f(r.get("floor_wall_s"), ".2f"),
                _f(r.get("ratio_to_floor"), ".1f"),
                _f(r.get("net_error_pct"), "+.2f") if "error" not in r else r["error"],
                _f(r.get("loadavg_1m_before"), ".1f"),
            ]
        )
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def plot(results: list[dict], path: Path) -> None:
    """Time and per-process peak memory against points, one line per scheduler/layout."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ok = [r for r in results if r.get("wall_s") and not r.get("same_as")]
    if not ok:
        return
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 5))
    series: dict[str, list[dict]] = {}
    for r in sorted(ok, key=lambda r: r["points"]):
        series.setdefault(f"{r.get('scheduler', 'default')}" + (" VPC" if r.get("layout") == "vpc" else ""), []).append(
            r
        )
    for label, rs in series.items():
        n = np.array([r["points"] for r in rs], dtype=float)
        a1.loglog(n, [r["wall_s"] for r in rs], "o-", label=f"estimate {label}")
        mem = [r.get("largest_process_mb") or r.get("peak_rss_mb") for r in rs]
        a2.loglog(n, mem, "o-", label=f"largest process {label}")
        if any(r.get("processes_sum_mb") for r in rs) and label.startswith(("local", "tcp")):
            a2.loglog(n, [r.get("processes_sum_mb") for r in rs], "x:", label=f"all processes {label}")
    floors: dict[int, float] = {}
    for r in ok:
        if r.get("floor_wall_s"):
            floors[r["points"]] = min(floors.get(r["points"], float("inf")), r["floor_wall_s"])
    fl = sorted(floors.items())
    if fl:
        a1.loglog(*zip(*fl, strict=True), "s--", color="gray", label="floor: read + 3 GeoTIFFs")
    a1.set_title("wall time")
    a1.set_ylabel("seconds")
    a2.axhline(1024, color="red", lw=0.8, label="1 GB (64 M pair, local:2)")
    a2.axhline(600, color="orange", lw=0.8, label="600 MB (paper pair as VPC, local:2)")
    a2.set_title("peak memory per process")
    a2.set_ylabel("MB")
    for ax in (a1, a2):
        ax.set_xlabel("points (before + after)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def update_readme(text: str) -> None:
    readme = HERE / "README.md"
    s = readme.read_text()
    if README_START not in s or README_END not in s:
        print("[bench] README.md has no bench markers; not updated")
        return
    a, rest = s.split(README_START, 1)
    _, b = rest.split(README_END, 1)
    readme.write_text(a + README_START + "\n" + text + "\n" + README_END + b)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--sizes",
        default=None,
        help=f"comma-separated scenes (paper, 1M, 4M, 16M, 64M, or e.g. 250k); default {DEFAULT_SIZES}",
    )
    ap.add_argument("--full", action="store_true", help=f"run {FULL_SIZES}")
    ap.add_argument(
        "--cmd",
        default=DEFAULT_CMD,
        help="command template; fields {before} {after} {out} {venv} {python} {repo}"
        f" (default: {DEFAULT_CMD!r})",
    )
    ap.add_argument("--venv", default=str(REPO / ".venv"), help="virtualenv of {venv}/{python}")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fmt", choices=["las", "laz"], default="las", help="input file format")
    ap.add_argument("--repeat", type=int, default=1, help="runs per scene; the fastest is kept")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per process")
    ap.add_argument(
        "--cache", default=None, help="scene cache (default $SOILVOLUME_BENCH_CACHE or ~/.cache/soilvolume-bench)"
    )
    ap.add_argument("--results", default=str(HERE / "results"), help="output directory")
    ap.add_argument("--keep-outputs", action="store_true", help="keep each run's output dir")
    ap.add_argument("--update-readme", action="store_true", help="rewrite the latest-results table in bench/README.md")
    ap.add_argument("--generate-only", action="store_true", help="only build the scene cache")
    ap.add_argument(
        "--scheduler",
        default="",
        help="comma-separated --scheduler values to run each scene with (e.g. none,local:2); "
        "default: the engine's default (auto)",
    )
    ap.add_argument(
        "--layout",
        choices=["file", "vpc"],
        default="file",
        help="inputs as one file per epoch, or as LAZ tiles grouped by a VPC",
    )
    ap.add_argument("--tile-m", type=float, default=50.0, help="--layout vpc: tile side (m)")
    args = ap.parse_args(argv)

    sizes = [s.strip() for s in (FULL_SIZES if args.full else (args.sizes or DEFAULT_SIZES)).split(",") if s.strip()]
    for s in sizes:
        scene_config(s)  # validate early
    root = Path(args.cache) if args.cache else cache_root()
    if args.generate_only:
        for s in sizes:
            b, a, _, _ = ensure_scene(s, args.seed, args.fmt, root)
            if args.layout == "vpc":
                ensure_tiles(b, args.tile_m), ensure_tiles(a, args.tile_m)
        return 0
    results_dir = Path(args.results)
    results_dir.mkdir(parents=True, exist_ok=True)
    runs = root / "runs"
    runs.mkdir(parents=True, exist_ok=True)

    results: list[dict] = []
    started = time.strftime("%Y-%m-%d %H:%M:%S %z")
    done: dict[str, dict] = {}  # config key -> result, so e.g. 4M (= the paper config) runs once
    schedulers = [x.strip() for x in args.scheduler.split(",")] if args.scheduler else [""]
    for s, sched in ((s, x) for s in sizes for x in schedulers):
        key = json.dumps(asdict(scene_config(s)), sort_keys=True) + sched
        if key in done:
            same = dict(done[key], scene=s, same_as=done[key]["scene"])
            print(f"[bench] {s}: same scene as {same['same_as']}, not run again", flush=True)
            results.append(same)
            continue
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
        if load is not None and load > 0.5 * (os.cpu_count() or 1):
            print(
                f"[bench] warning: load average {load:.2f} on {os.cpu_count()} cores: other "
                "processes compete, timings will be pessimistic",
                flush=True,
            )
        r = run_scene(s, args, root, runs, sched)
        r["loadavg_1m_before"] = load
        done[key] = r
        results.append(r)
    doc = {
        "date": started,
        "machine": machine(),
        "command": args.cmd,
        "seed": args.seed,
        "fmt": args.fmt,
        "repeat": args.repeat,
        "cache": str(root),
        "scenes": results,
    }
    (results_dir / "latest.json").write_text(json.dumps(doc, indent=2))
    plot(results, results_dir / "latest.png")
    tab = table(results)
    m = doc["machine"]
    dirty = " (dirty)" if m["git_dirty"] else ""
    header = (
        f"{started} · {m['cpu']} · {m['cores']} cores · {m['mem_gb']} GB · "
        f"Python {m['python']} · commit {m['git_commit']}{dirty}"
        f"\n\ncommand: `{args.cmd}`; best of {args.repeat}; x floor = wall / floor wall; "
        "load = 1-min load average before the scene\n"
    )
    print()
    print(header)
    print(tab)
    print(f"\n[bench] wrote {results_dir / 'latest.json'} and {results_dir / 'latest.png'}")
    if args.update_readme:
        update_readme(header + "\n" + tab)
    return 0 if all("error" not in r for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
