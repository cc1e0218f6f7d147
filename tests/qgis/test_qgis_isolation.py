"""The plugin on a stock QGIS, with nothing of the dev venv on any path (Debian's /usr/bin/python3
and qgis_process): install the zip into a clean profile, ``qgis_process run
soilvolume:installdependencies``, then the estimate on both real pairs gives the command line's
nets; four runs in worker threads of one QGIS process all finish, and after runs of every
algorithm no engine library is loaded in QGIS; QGIS's real Batch dialog runs two pairs under Xvfb
and QGIS is still running afterwards."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
REAL = Path("/work/shared/data/real") if Path("/work/shared/data/real").is_dir() else REPO.parent / "shared/data/real"
STOCK_PYTHON = "/usr/bin/python3"  # the Python QGIS itself uses on Debian
QGIS_PROCESS = shutil.which("qgis_process")
PAIRS = {
    "autzen": ("autzen_bmx_2010.las", "autzen_bmx_2023.las"),
    "tommy": ("tommy_thompson_park_2015.laz", "tommy_thompson_park_2023.laz"),
}
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(QGIS_PROCESS is None or not Path(STOCK_PYTHON).is_file(), reason="needs Debian's QGIS"),
    pytest.mark.skipif(not (REAL / "autzen_bmx_2010.las").is_file(), reason="real data not present"),
]


def stock_env(**extra: str) -> dict[str, str]:
    """This process's environment without anything of the dev venv or of pytest-qgis."""
    venv = str(REPO / ".venv")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "SOILVOLUME_", "QGIS_", "VIRTUAL_ENV"))}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if not p.startswith(venv))
    env.update(QT_QPA_PLATFORM="offscreen", **extra)
    return env


def run(command: list[str], env: dict[str, str], timeout: float = 900) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=timeout, cwd=env.get("HOME", "/"))
    return done, time.perf_counter() - t0


def results_of(done: subprocess.CompletedProcess) -> dict:
    assert done.returncode == 0, done.stderr[-3000:] + done.stdout[-3000:]
    return json.loads(done.stdout[done.stdout.index("{") :])["results"]


@pytest.fixture(scope="module")
def installed(plugin_zip, tmp_path_factory) -> dict:
    """The zip installed into a clean profile, its environment made by qgis_process."""
    root = tmp_path_factory.mktemp("clean")
    config = root / "config"
    plugins = config / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    zipfile.ZipFile(plugin_zip).extractall(plugins)
    env = stock_env(QGIS_CUSTOM_CONFIG_PATH=str(config), HOME=str(root))
    enabled, _ = run([QGIS_PROCESS, "plugins", "enable", "soilvolume_qgis"], env, 120)
    assert enabled.returncode == 0, enabled.stderr
    first, install_s = run([QGIS_PROCESS, "run", "soilvolume:installdependencies", "--json"], env)
    results = results_of(first)
    again, again_s = run([QGIS_PROCESS, "run", "soilvolume:installdependencies", "--json"], env)
    results_of(again)
    folder = Path(results["ENVIRONMENT"])
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6
    figures = {"install_s": install_s, "again_s": again_s, "size_mb": size}
    print("install figures", figures)
    return {"env": env, "plugins": plugins, "folder": folder, "results": results, **figures}


def test_install_makes_a_tested_environment_in_the_profile(installed):
    assert installed["folder"].is_relative_to(installed["plugins"].parents[1])  # in the profile
    assert json.loads(installed["results"]["VERSIONS"])["pyproj"] == "3.7.2"  # not Debian's 3.4.1
    assert installed["again_s"] < 20, installed  # a re-run finds everything there


@pytest.fixture(scope="module")
def cli_nets(tmp_path_factory) -> dict[str, tuple[float, float]]:
    """{pair: (net, seconds)} of the command line (the dev venv) on both real pairs."""
    nets = {}
    for pair, names in sorted(PAIRS.items()):
        out = tmp_path_factory.mktemp(f"cli-{pair}") / "result"
        cli, seconds = run(
            [str(REPO / ".venv/bin/soilvolume"), "estimate", *(str(REAL / n) for n in names), "--out", str(out)],
            dict(os.environ),
        )
        assert cli.returncode == 0, cli.stderr
        nets[pair] = (json.loads((out / "report.json").read_text())["volume_m3"]["net"], seconds)
    return nets


@pytest.mark.parametrize("pair", sorted(PAIRS))
def test_real_pairs_give_the_command_lines_nets(installed, cli_nets, pair, tmp_path):
    before, after = (str(REAL / name) for name in PAIRS[pair])
    done, qgis_s = run(
        [
            QGIS_PROCESS,
            "run",
            "soilvolume:estimatevolumechange",
            "--json",
            "--",
            f"BEFORE={before}",
            f"AFTER={after}",
            f"DIFFERENCE={tmp_path / 'd.tif'}",
        ],
        installed["env"],
    )
    net = results_of(done)["NET_VOLUME"]
    cli_net, cli_s = cli_nets[pair]
    print(f"{pair}: QGIS {net:+.1f} m3 in {qgis_s:.1f} s, CLI {cli_net:+.1f} m3 in {cli_s:.1f} s")
    assert net == pytest.approx(cli_net, rel=0.005)


def test_four_worker_threads_and_no_engine_library_in_qgis(installed, tmp_path):
    env = dict(installed["env"], SOILVOLUME_ENGINE_ENV=str(installed["folder"]))
    done, seconds = run(
        [STOCK_PYTHON, str(HERE / "thread_session.py"), str(installed["plugins"]), str(tmp_path), str(REAL)], env
    )
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout.split("RESULT", 1)[1])
    runs = summary["runs"]
    assert [r["ok"] for r in runs] == [True] * 4, runs
    nets = {r["pair"]: r["net"] for r in runs}
    for r in runs:
        assert r["net"] == pytest.approx(nets[r["pair"]], rel=1e-9)  # parallel runs agree
    assert summary["others"]["pointcloudtodem"] > 1000 and summary["others"]["registerpointclouds"] < 1.0
    assert summary["new_modules"] == {}, summary["new_modules"]  # nothing of the engine's stack in QGIS
    assert summary["wheel_libraries"] == [], summary["wheel_libraries"]  # no second PROJ or GDAL
    assert summary["children"] == [], summary["children"]  # no engine process left behind
    print(f"four threaded runs in {summary['seconds']:.1f} s")


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run is not installed")
def test_batch_dialog_runs_two_pairs_and_qgis_keeps_running(cli_nets, tmp_path):
    """QGIS's Batch dialog, two rows (Autzen, Tommy Thompson) run by its Run button's code on
    pooled threads, results loaded: each row's net is the command line's, each run's layers are
    in a group of its own named after its pair with the change areas on top of the difference,
    and QGIS's own Processing still
    runs in that process afterwards, which then exits cleanly (no SIGSEGV)."""
    env = stock_env(
        SOILVOLUME_ENGINE_ENV=os.environ["SOILVOLUME_ENGINE_ENV"], QGIS_CUSTOM_CONFIG_PATH=str(tmp_path / "p")
    )
    env.pop("QT_QPA_PLATFORM")
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    (plugins / "soilvolume_qgis").symlink_to(REPO, target_is_directory=True)
    pairs = [",".join(str(REAL / n) for n in PAIRS[p]) for p in ("autzen", "tommy")]
    command = [
        "xvfb-run",
        "-a",
        "-s",
        "-screen 0 1400x1000x24",
        STOCK_PYTHON,
        str(HERE / "batch_session.py"),
        str(plugins),
        str(tmp_path),
        *pairs,
    ]
    done, _ = run(command, env, 900)
    assert done.returncode == 0, done.stderr[-3000:]  # no SIGSEGV: QGIS ran to its clean exit
    summary = json.loads(done.stdout.split("RESULT", 1)[1])
    for net, pair in zip(summary["nets"], ("autzen", "tommy"), strict=True):
        assert net == pytest.approx(cli_nets[pair][0], rel=0.005), (pair, summary)
    groups = summary["groups"]
    for pair in ("autzen", "tommy"):
        before, after = (name.split(".")[0] for name in PAIRS[pair])
        (layers,) = [v for k, v in groups.items() if k.startswith(f"Soil volume: {before} → {after} (run 1, ")]
        assert layers == [f"Areas of significant change ({after})", f"Difference ({after})"], groups
    assert groups[""] == [], groups  # nothing outside the runs' groups
    assert summary["python_errors"] == [] and "not correctly generated" not in summary["log"], summary["log"][-2000:]
    after = summary["after"]  # native:rasterlayerstatistics on row 1's difference, after the batch
    assert after["min"] < 0 < after["max"] and abs(after["mean"]) < 1.0, after
    print(f"Batch dialog, two rows: {summary['seconds']:.1f} s")
