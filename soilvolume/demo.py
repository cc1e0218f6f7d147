"""``soilvolume demo``: a seeded synthetic pair with known volumes, run end to end."""

from __future__ import annotations

import json
from pathlib import Path

from .api import Hooks, estimate
from .options import Options
from .synthetic import SceneConfig, make_pair, write_pair


def run_demo(out: Path, size: str = "small", seed: int = 0) -> int:
    cfg = SceneConfig.paper() if size == "paper" else SceneConfig.small()
    data = out / "data"
    data.mkdir(parents=True, exist_ok=True)
    before, after, truth_path = write_pair(make_pair(seed, cfg), data, "laz")
    truth = json.loads(truth_path.read_text())
    print(f"synthetic pair ({size}, seed {seed}) in {data}")
    res = estimate(before, after, out / "result", Options(seed=seed), overwrite=True,
                   hooks=Hooks(progress=lambda p, m: print(f"[{p:5.1f}%] {m}", flush=True)))
    v, u = res.report["volume_m3"], res.report["volume_uncompensated_m3"]
    print(f"{'':14}{'estimated':>12}{'uncompensated':>15}{'true':>12}{'error':>9}")
    for k in ("net", "cut", "fill"):
        err = (v[k] - truth[k]) / abs(truth[k]) * 100 if truth[k] else float("nan")
        print(f"{k + ' (m3)':14}{v[k]:12.2f}{u[k]:15.2f}{truth[k]:12.2f}{err:8.2f}%")
    print(f"results in {out / 'result'} (report.html, difference.tif, ...)")
    return 0
