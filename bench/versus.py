"""The project beside CloudCompare and the read floor on the same pair, interleaved (issue 22).

    .venv/bin/python bench/versus.py                      # paper pair, 5 rounds
    .venv/bin/python bench/versus.py --sizes paper --repeat 7 --scheduler none,local:2

Each round runs, one after the other: ``soilvolume estimate`` (defaults, or ``--scheduler X``),
the read floor (``bench/floor.py``: laspy chunked read of both files + three GeoTIFFs, Python
start-up included) and CloudCompare's command line (ICP, then the 2.5D volume between the two
clouds on the project's cell; CloudCompare reads PLY, so each pair is converted to binary PLY
once, cached beside the LAS files and not charged). Interleaving spreads a shared machine's load
over all three; the table gives medians of wall time and of CPU (user + sys) of each command
(with the processes it leaves to finish after it: a local cluster's forkserver and workers),
its peak RSS, and the ratios project / CloudCompare and project / floor. CloudCompare is Debian's
``cloudcompare`` package (``scripts/setup.sh`` installs it); without it the CloudCompare columns
are skipped with one line saying so. Results: ``bench/results/versus.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from run_bench import REPO, cache_root, ensure_scene, warm  # noqa: E402

CC_NAMES = ("CloudCompare", "cloudcompare")


def cloudcompare() -> str | None:
    """The CloudCompare executable, None when it is not installed."""
    return next((p for p in map(shutil.which, CC_NAMES) if p), None)


def ensure_ply(las: Path) -> Path:
    """``las`` as binary little-endian PLY of float64 x, y, z (cached beside it)."""
    ply = las.with_suffix(".ply")
    if ply.exists() and ply.stat().st_mtime >= las.stat().st_mtime:
        return ply
    import laspy
    import numpy as np

    tmp = ply.with_suffix(".ply.tmp")
    with laspy.open(las) as reader, open(tmp, "wb") as f:
        n = reader.header.point_count
        head = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
        f.write((head + "".join(f"property double {a}\n" for a in "xyz") + "end_header\n").encode())
        for pts in reader.chunk_iterator(1_000_000):
            a = np.empty(len(pts), [("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
            a["x"], a["y"], a["z"] = pts.x, pts.y, pts.z
            f.write(a.tobytes())
    os.replace(tmp, ply)
    return ply


def cc_argv(exe: str, before_ply: Path, after_ply: Path, cell: float) -> list[str]:
    """CloudCompare's CLI: after registered onto before by ICP (its defaults), then the 2.5D
    volume with before as the ground and after as the ceiling, on a ``cell`` m grid."""
    opened = [a for p in (after_ply, before_ply) for a in ("-O", "-GLOBAL_SHIFT", "AUTO", str(p))]
    return [exe, "-SILENT", "-AUTO_SAVE", "OFF", *opened, "-ICP", "-VOLUME", "-GRID_STEP", f"{cell:g}"]


GNU_TIME = Path("/usr/bin/time")


def run(argv: list[str], log: Path, env: dict | None = None, timeout: float = 1800) -> dict:
    """Wall seconds, CPU seconds (user + sys) and peak RSS (MB) of one command: GNU time's
    figures when it is there (Linux keeps a forked child's peak across exec, so os.wait4 of a
    child of this large process reports at least this process's RSS), else os.wait4's. The CPU
    includes processes the command left to finish after it (:func:`_orphans_cpu`)."""
    if GNU_TIME.exists():
        out = log.with_suffix(".time")
        r = _wait4([str(GNU_TIME), "-f", "%U %S %M", "-o", str(out), *argv], log, env, timeout)
        if r["rc"] == 0 and out.exists():
            user, system, kb = out.read_text().split()[-3:]
            r.update(cpu_s=float(user) + float(system) + _orphans_cpu(), peak_rss_mb=int(kb) / 1024.0)
        return r
    r = _wait4(argv, log, env, timeout)
    r["cpu_s"] += _orphans_cpu()
    return r


def _become_subreaper() -> bool:
    """Linux: descendants whose parent exits are handed to this process (not to init), so their
    CPU can be counted: a local Dask cluster's forkserver and the workers it forked outlive the
    command by a moment and are nobody's waited child otherwise (PR_SET_CHILD_SUBREAPER)."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0


SUBREAPER = False  # set by main(): :func:`_become_subreaper`


def _orphans_cpu(timeout: float = 30.0) -> float:
    """CPU seconds (user + sys) of the orphans handed to this process, each waited for (with
    their own waited children) until none is left or ``timeout`` passes."""
    total, deadline = 0.0, time.monotonic() + timeout
    while SUBREAPER and time.monotonic() < deadline:
        try:
            pid, _status, ru = os.wait4(-1, os.WNOHANG)
        except ChildProcessError:
            break
        if pid:
            total += ru.ru_utime + ru.ru_stime
        else:
            time.sleep(0.01)
    return total


def _wait4(argv: list[str], log: Path, env: dict | None, timeout: float) -> dict:
    t = time.perf_counter()
    with open(log, "w") as lf:
        proc = subprocess.Popen(argv, stdout=lf, stderr=subprocess.STDOUT, env=env)
        deadline = t + timeout
        while True:
            pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                proc.kill()
            time.sleep(0.005)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return {
        "rc": proc.returncode,
        "wall_s": time.perf_counter() - t,
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "peak_rss_mb": ru.ru_maxrss / 1024.0,
    }


def _median(runs: list[dict], key: str) -> float | None:
    vals = [r[key] for r in runs if r.get("rc") == 0]
    return statistics.median(vals) if vals else None


def compare(name: str, scheduler: str, rounds: int, venv: Path, runs_dir: Path, layout: str = "file") -> dict:
    """``rounds`` interleaved rounds of project, floor and CloudCompare on scene ``name``."""
    before, after, truth, _ = ensure_scene(name, 0, "las", cache_root())
    inputs = (before, after)
    if layout == "vpc":
        from run_bench import ensure_tiles

        inputs = (ensure_tiles(before, 50.0), ensure_tiles(after, 50.0))
    exe = cloudcompare()
    if exe is None:
        print("[versus] CloudCompare is not installed (apt-get install cloudcompare): its columns are skipped")
    plys = (ensure_ply(before), ensure_ply(after)) if exe else None
    warm([before, after, *(plys or ())])
    scratch = runs_dir / f"versus-{name}-cc"  # CloudCompare writes its reports beside the clouds: here, not the cache
    shutil.rmtree(scratch, ignore_errors=True)
    if plys:
        scratch.mkdir(parents=True)
        plys = tuple(_linked(p, scratch) for p in plys)
    out = runs_dir / f"versus-{name}"
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: compiled modules
    est = [str(venv / "bin" / "soilvolume"), "estimate", *map(str, inputs), "--out", str(out), "--overwrite"]
    if scheduler:
        est += ["--scheduler", scheduler]
    fl = [str(venv / "bin" / "python"), str(HERE / "floor.py"), str(before), str(after), str(out) + "-floor"]
    res: dict = {"scene": name, "scheduler": scheduler or "default", "layout": layout, "project": [], "floor": []}
    res["cloudcompare"] = [] if exe else None
    cell = None
    for i in range(rounds):
        shutil.rmtree(out, ignore_errors=True)
        res["project"].append(run(est, runs_dir / "versus-project.log", env))
        if cell is None and (out / "report.json").exists():
            rep = json.loads((out / "report.json").read_text())
            cell = rep["grid"]["cell_m"]
            res["report"] = {k: rep.get(k) for k in ("volume_m3", "uncertainty_m3", "timings_s")}
        res["floor"].append(run(fl + ["--cell", str(cell or 0.5)], runs_dir / "versus-floor.log", env))
        shutil.rmtree(str(out) + "-floor", ignore_errors=True)
        if exe:
            cc = cc_argv(exe, plys[0], plys[1], cell or 0.5)
            res["cloudcompare"].append(run(cc, runs_dir / "versus-cc.log", env))
        done = ", ".join(_line(res, k, -1) for k in _kinds(res))
        print(f"[versus] {name} round {i + 1}/{rounds}: {done}", flush=True)
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(scratch, ignore_errors=True)
    res["truth_net_m3"] = json.loads(Path(truth).read_text())["net"]
    res["load"] = os.getloadavg()
    return res


def _linked(path: Path, folder: Path) -> Path:
    """``path`` as a symbolic link in ``folder`` (a copy where links are not allowed)."""
    link = folder / path.name
    try:
        link.symlink_to(path)
    except OSError:
        shutil.copyfile(path, link)
    return link


def _kinds(res: dict) -> list[str]:
    return [k for k in ("project", "floor", "cloudcompare") if res.get(k) is not None]


def _line(res: dict, kind: str, i: int) -> str:
    r = res[kind][i]
    return f"{kind} {r['wall_s']:.2f} s" if r["rc"] == 0 else f"{kind} exit {r['rc']}"


def summary(res: dict) -> str:
    """The medians and the two ratios, as a Markdown table."""
    rows = ["| command | wall s | CPU s | peak MB |", "|---|---|---|---|"]
    med = {}
    for kind in _kinds(res):
        med[kind] = {k: _median(res[kind], k) for k in ("wall_s", "cpu_s", "peak_rss_mb")}
        m = med[kind]
        rows.append(f"| {kind} | " + " | ".join("-" if v is None else f"{v:.2f}" for v in m.values()) + " |")
    p = med["project"]["wall_s"]
    ratios = []
    for kind, label in (("cloudcompare", "CloudCompare"), ("floor", "read floor")):
        other = med.get(kind, {}).get("wall_s")
        if p and other:
            res[f"project_over_{kind}"] = p / other
            ratios.append(f"project / {label} = {p / other:.2f}")
    head = f"{res['scene']} [{res['scheduler']}, {res['layout']}], medians of {len(res['project'])} interleaved rounds"
    return head + f" (load {res['load'][0]:.1f}):\n" + "\n".join(rows) + "\n" + "; ".join(ratios)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="paper", help="comma-separated scenes (as run_bench.py)")
    ap.add_argument("--repeat", type=int, default=5, help="interleaved rounds (medians are reported)")
    ap.add_argument("--scheduler", default="", help="comma-separated --scheduler values (default: the default)")
    ap.add_argument("--layout", choices=("file", "vpc"), default="file", help="vpc: the project reads 50 m tiles")
    ap.add_argument("--venv", default=str(REPO / ".venv"), help="environment with the soilvolume command")
    ap.add_argument("--results", default=str(HERE / "results"), help="output directory")
    args = ap.parse_args(argv)
    global SUBREAPER
    SUBREAPER = _become_subreaper()
    runs = Path(args.results) / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    results = []
    for name in args.sizes.split(","):
        for sched in args.scheduler.split(","):
            res = compare(name.strip(), sched.strip(), args.repeat, Path(args.venv), runs, args.layout)
            print(summary(res), flush=True)
            results.append(res)
    (Path(args.results) / "versus.json").write_text(json.dumps(results, indent=1, default=str))
    return 0 if all(r["rc"] == 0 for res in results for r in res["project"]) else 1


if __name__ == "__main__":
    sys.exit(main())
