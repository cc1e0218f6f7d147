"""``soilvolume pipeline --emit`` writes PDAL pipelines that reproduce the engine's preparation."""

from __future__ import annotations

import json

from conftest import run_cli

from soilvolume.pipelines.pipeline import load_pipeline


def test_emitted_pipelines_run_and_match_the_direct_estimate(misaligned_pair, misaligned_result, tmp_path):
    before, after, truth = misaligned_pair
    p = run_cli("pipeline", before, after, "--emit", tmp_path / "pipes")
    assert p.returncode == 0, p.stderr
    b_json, a_json = tmp_path / "pipes" / "before.json", tmp_path / "pipes" / "after.json"
    stages_b = load_pipeline(b_json)
    types = [s["type"] for s in stages_b]
    assert types[0] == "readers.las" and "filters.crop" in types and "filters.outlier" in types
    assert json.loads(b_json.read_text())["pipeline"][0]["filename"] == str(before)
    out = tmp_path / "est"
    p = run_cli(
        "estimate", before, after, "--before-pipeline", b_json, "--after-pipeline", a_json, "--out", out, "--quiet"
    )
    assert p.returncode == 0, p.stderr
    net = json.loads((out / "report.json").read_text())["volume_m3"]["net"]
    direct = misaligned_result[0].report["volume_m3"]["net"]
    assert abs(net - direct) / abs(direct) < 0.01
    assert abs(net - truth["net"]) / truth["net"] < 0.02
    # the pipeline's own writer ran, into the run's output folder (writers never write outside it)
    assert (out / "before_prepared.laz").exists() and not (tmp_path / "pipes" / "before_prepared.laz").exists()


def test_pipeline_help():
    p = run_cli("pipeline", "--help")
    assert p.returncode == 0 and "--emit" in p.stdout and "--radius" in p.stdout
