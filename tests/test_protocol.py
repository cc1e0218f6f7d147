"""``--progress jsonl``, the command line's protocol for programs (the QGIS plugin): every line of
standard output is one JSON object, progress moves, the result comes last; an option out of its
range is an ``error`` line naming the option's field, and texts name options by key; ``cancel``
on standard input stops a run with nothing written; each command takes the options the option
table declares for it; ``dem --bounds-crs`` takes an extent in another CRS."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from conftest import run_cli, write_scene

from soilvolume.options import COMMANDS, command_fields


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    before, after, _ = write_scene(tmp_path_factory.mktemp("protocol"), 0)
    return before, after


def events(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines()]  # every line is JSON, or this fails


def test_dem_streams_progress_then_its_result(pair, tmp_path):
    done = run_cli("dem", pair[0], "--out", tmp_path / "dem.tif", "--cell", "2", "--progress", "jsonl")
    assert done.returncode == 0, done.stderr
    lines = events(done.stdout)
    progress = [e["percent"] for e in lines if e["type"] == "progress"]
    assert len(progress) >= 3 and progress == sorted(progress) and progress[-1] == 100
    result = lines[-1]
    assert result["type"] == "result" and result["command"] == "dem" and result["cell_m"] == 2.0
    assert result["valid_cells"] > 1000 and (tmp_path / "dem.tif").is_file()
    assert "{" not in done.stderr  # nothing of the protocol on standard error


def test_an_option_out_of_range_is_an_error_line_naming_its_field(pair, tmp_path):
    done = run_cli("dem", pair[0], "--out", tmp_path / "dem.tif", "--cell", "0.001", "--progress", "jsonl")
    assert done.returncode == 1
    error = events(done.stdout)[-1]
    assert error["type"] == "error" and error["field"] == "cell" and error["reason"], error
    assert error["exit"] == 1 and not (tmp_path / "dem.tif").exists()


def test_errors_name_options_by_key_and_the_command_line_words_them_as_flags(pair, tmp_path):
    args = ["estimate", *pair, "--out", tmp_path / "out", "--ground", "filter", "--scheduler", "threads:2"]
    keyed = events(run_cli(*args, "--progress", "jsonl").stdout)[-1]
    assert keyed["type"] == "error" and keyed["message"].startswith("{opt:ground=filter} needs whole clouds"), keyed
    assert "use {opt:scheduler=none}" in keyed["message"] and "--" not in keyed["message"]
    text = run_cli(*args)
    assert text.returncode == 1 and "{" not in text.stderr
    assert "error: --ground filter needs whole clouds: use --scheduler none" in text.stderr, text.stderr


def test_cancel_on_stdin_stops_the_run_and_writes_nothing(pair, tmp_path):
    out = tmp_path / "result"
    proc = subprocess.Popen(
        [sys.executable, "-m", "soilvolume", "estimate", *map(str, pair), "--out", str(out), "--progress", "jsonl"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        for line in proc.stdout:
            event = json.loads(line)
            if event["type"] == "progress" and event["percent"] >= 20:  # registering
                break
        t0 = time.perf_counter()
        proc.stdin.write("cancel\n")
        proc.stdin.flush()
        rest = events(proc.stdout.read())
        code = proc.wait(timeout=30)
        seconds = time.perf_counter() - t0
    finally:
        proc.kill()
        proc.wait(timeout=10)
    assert code != 0 and rest[-1]["type"] == "error", rest[-3:]
    assert seconds < 5, seconds
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == []


def subcommand_flags() -> dict[str, set[str]]:
    """Each sub-command's option strings, from the command line's own parser."""
    import argparse

    from soilvolume.cli import build_parser

    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
    return {name: {s for a in p._actions for s in a.option_strings} for name, p in sub.choices.items()}  # noqa: SLF001


def test_each_command_takes_the_options_declared_for_it():
    flags = subcommand_flags()
    every = {"--" + f.name.replace("_", "-") for c in COMMANDS for f in command_fields(c)} - {"--keep-registered-cloud"}
    for command in COMMANDS:
        declared = {"--" + f.name.replace("_", "-") for f in command_fields(command)} - {"--keep-registered-cloud"}
        assert declared <= flags[command], (command, declared - flags[command])
        assert not (every - declared) & flags[command], (command, (every - declared) & flags[command])
    assert {"--georeferencing", "--max-gps-tilt", "--threads", "--ground-window"} <= flags["register"]
    assert {"--cell", "--statistic", "--ground", "--ground-slope"} <= flags["dem"]


def test_bounds_in_another_crs_give_the_same_grid(pair, tmp_path):
    import pyproj
    import rasterio

    box = (500010.0, 3900010.0, 500050.0, 3900040.0)  # in the cloud's CRS (EPSG:32654)
    lonlat = pyproj.Transformer.from_crs(32654, 4326, always_xy=True).transform_bounds(*box)
    grids = []
    for name, bounds, extra in (("utm", box, []), ("lonlat", lonlat, ["--bounds-crs", "EPSG:4326"])):
        dest = tmp_path / f"{name}.tif"
        done = run_cli("dem", pair[0], "--out", dest, "--cell", "2", "--bounds", *map(repr, bounds), *extra)
        assert done.returncode == 0, done.stderr
        with rasterio.open(dest) as src:
            grids.append(src.bounds)
    utm, lonlat_grid = grids
    assert lonlat_grid.left <= utm.left and lonlat_grid.bottom <= utm.bottom  # the box around the extent
    assert lonlat_grid.right >= utm.right and lonlat_grid.top >= utm.top
    assert lonlat_grid.right - lonlat_grid.left < (utm.right - utm.left) + 6  # and not much more
