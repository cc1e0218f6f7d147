"""The engine's lock on every system QGIS users have: one Open3D version wherever it has wheels,
each Mac checked on the oldest macOS the plugin says it supports, alone (pip accepts wheels for
the tag given and older ones, so one tag tests exactly that macOS; several tested only the
newest), and that oldest macOS really is the oldest: one version below, pip finds no wheels."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PIP = str(Path(sys.executable).parent / "pip")


def load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


check_lock = load("check_lock", ROOT / "scripts" / "check_lock.py")
platforms = load("plugin_platforms", ROOT / "plugin" / "platforms.py")


def pins(target: str) -> dict[str, str]:
    _tags, python, env3 = check_lock.TARGETS[target]
    return dict(pin.split("==") for pin in check_lock.pins_for(python, env3))


def test_each_mac_is_checked_alone_on_its_oldest_supported_macos():
    macs = {name: tags for name, (tags, _py, _env) in check_lock.TARGETS.items() if name.startswith("macOS")}
    assert sorted(macs.values()) == [["macosx_13_0_x86_64"], ["macosx_14_0_arm64"]], macs
    assert platforms.MAC_MINIMUM == {"arm64": (14, 0), "x86_64": (13, 0)}  # what the plugin and docs/install.md say


def test_one_open3d_version_wherever_it_has_wheels():
    """Open3D 0.20 has wheels for Linux, Windows and Apple silicon; 0.19 is the last for Intel Macs."""
    versions = {name: pins(name).get("open3d") or pins(name).get("open3d-cpu") for name in check_lock.TARGETS}
    intel_mac = next(n for n in versions if n.startswith("macOS") and "x86_64" in n)
    assert versions.pop(intel_mac) == "0.19.0"
    assert set(versions.values()) == {"0.20.0"}, versions


def dry_run(tags: list[str], python: str, env3) -> tuple[int, str]:
    reqs = "\n".join(check_lock.pins_for(python, env3))
    command = [PIP, "install", "--dry-run", "--quiet", "--no-deps", "--only-binary=:all:", "--ignore-installed"]
    command += ["--target", "/nonexistent-dry-run", "--python-version", python, "-r", "/dev/stdin"]
    command += [arg for tag in tags for arg in ("--platform", tag)]
    run = subprocess.run(command, input=reqs + "\n", capture_output=True, text=True, timeout=900)
    return run.returncode, run.stdout + run.stderr


@pytest.mark.slow
def test_the_lock_resolves_on_every_target_and_not_one_macos_below():
    """pip's dry run against PyPI's metadata (needs the index): every target resolves; a Mac one
    version older than MAC_MINIMUM is refused for pyproj (the plugin refuses it before pip)."""
    jobs = {name: (tags, python, env3) for name, (tags, python, env3) in check_lock.TARGETS.items()}
    for machine, (major, minor) in platforms.MAC_MINIMUM.items():
        older = (major - 1, minor) if major > 11 else (10, 15)
        jobs[f"below {machine}"] = ([check_lock.mac_tag(machine, older)], "3.12", ("darwin", machine, "Darwin"))
    with ThreadPoolExecutor(4) as pool:
        done = dict(zip(jobs, pool.map(lambda job: dry_run(*job), jobs.values()), strict=True))
    for name, (code, said) in done.items():
        if name.startswith("below"):
            assert code != 0 and "No matching distribution found for pyproj" in said, (name, said[-800:])
        else:
            assert code == 0, (name, said[-800:])
