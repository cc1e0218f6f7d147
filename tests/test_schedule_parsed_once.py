"""``--scheduler`` is parsed once per run, where its options become a run (issue 52): the run's
context carries the typed :class:`Schedule` and every later use (the backend, the design route's
note, the tiled backend, report.json) reads it. Before, a CLI estimate parsed it three times (the
CLI's and the API's option checks, then the backend choice) and a design run twice."""

from __future__ import annotations

import json
import sys

import pytest
from conftest import write_scene
from designs import write_surface

from soilvolume import api
from soilvolume.cli import main
from soilvolume.core.hooks import Hooks
from soilvolume.distributed import schedule
from soilvolume.options import Options
from soilvolume.scenes.config import SceneConfig
from soilvolume.scenes.series import write_series
from soilvolume.validate import OptionError


@pytest.fixture
def parses(monkeypatch) -> list[str]:
    """The values :func:`schedule.parse` is called with, wherever it is imported by name."""
    calls: list[str] = []
    original = schedule.parse

    def counted(spec: str):
        calls.append(spec)
        return original(spec)

    for module in [m for name, m in sys.modules.items() if name.startswith("soilvolume")]:
        if getattr(module, "parse", None) is original:
            monkeypatch.setattr(module, "parse", counted)
    return calls


def test_an_estimate_parses_the_scheduler_once_and_reports_its_value(parses, tmp_path):
    before, after, _ = write_scene(tmp_path / "in")
    args = ["estimate", before, after, "--out", tmp_path / "out", "--scheduler", "threads:2", "--quiet"]
    assert main([str(a) for a in args]) == 0
    assert parses == ["threads:2"]
    assert json.loads((tmp_path / "out" / "report.json").read_text())["engine"]["scheduler"] == "threads:2"


def test_a_design_run_parses_the_scheduler_once_and_runs_in_this_process(parses, tmp_path):
    _, after, _ = write_scene(tmp_path / "in")
    design = write_surface(tmp_path / "in" / "design.tif", 0, SceneConfig.small())
    said: list[str] = []
    done = api.estimate(design, after, tmp_path / "out", Options(scheduler="local:2"), hooks=Hooks(log=said.append))
    assert parses == ["local:2"]
    assert "--scheduler: a run against a surface runs in this process" in said
    assert "engine" not in done.report  # in memory: no tiles, no cluster


def test_a_series_parses_the_scheduler_once(parses, tmp_path):
    paths, _ = write_series(tmp_path / "in", density=(1.5, 2.5), datum=True)
    assert main(["series", *map(str, paths), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert parses == ["auto"]


@pytest.mark.parametrize("run", ["estimate", "series"])
def test_a_bad_scheduler_is_refused_before_any_file_is_read(tmp_path, run):
    """The inputs do not exist: the scheduler, parsed first, is what the error names."""
    missing = [tmp_path / "a.las", tmp_path / "b.las", tmp_path / "c.las"]
    options = Options(scheduler="local:0")
    with pytest.raises(OptionError, match=r"^--scheduler: expected none") as info:
        if run == "estimate":
            api.estimate(missing[0], missing[1], tmp_path / "out", options)
        else:
            api.series(missing, tmp_path / "out", options)
    assert info.value.field == "scheduler" and not (tmp_path / "out").exists()
