"""``soilvolume demo``: a seeded synthetic pair with known volumes, run end to end."""

from __future__ import annotations

import json
from pathlib import Path

from ..api import Hooks, estimate
from ..core.outputs import os_errors, output_dir
from ..options import Options
from ..validate import check_number
from .synthetic import SceneConfig, write_pair_streaming


def run_demo(out: Path, size: str = "small", seed: int = 0) -> int:
    cfg = SceneConfig.paper() if size == "paper" else SceneConfig.small()
    check_number("seed", seed, {"lo": 0, "hi": 2**31 - 1}, integer=True)
    with output_dir(out, [], True, ("data", "result")) as staged, os_errors(staged.final):
        data = staged.path("data")
        data.mkdir()
        before, after, truth_path = write_pair_streaming(seed, cfg, data, "laz")  # make_pair's bytes
        truth = json.loads(truth_path.read_text())
        print(f"synthetic pair ({size}, seed {seed}) in {out / 'data'}")
        hooks = Hooks(progress=lambda p, m: print(f"[{p:5.1f}%] {m}", flush=True))
        res = estimate(before, after, staged.path("result"), Options(seed=seed), overwrite=True, hooks=hooks)
    r = res.report
    rows = [
        ("all compared cells", r["volume_m3"]),
        ("change areas", r["volume_change_areas_m3"]),
        ("uncompensated", r["volume_uncompensated_m3"]),
        ("paper plane d_i", r["volume_paper_plane_m3"]),
    ]
    print(f"{'volumes (m3)':22}{'net':>10}{'cut':>10}{'fill':>10}   net error")
    print(f"{'true':22}{truth['net']:10.2f}{truth['cut']:10.2f}{truth['fill']:10.2f}")
    for name, v in rows:
        err = (v["net"] - truth["net"]) / abs(truth["net"]) * 100
        print(f"{name:22}{v['net']:10.2f}{v['cut']:10.2f}{v['fill']:10.2f}   {err:+.2f} %")
    print(f"95 % uncertainty of the net: +-{r['uncertainty_m3']['net']:.2f} m3")
    print(f"results in {out / 'result'} (report.html, difference.tif, ...)")
    return 0
