"""Does plugin/engine-lock.txt resolve to wheels on every platform QGIS users have?

For each target (platform tags, Python version) the lock's environment markers are evaluated for
that target (pip evaluates them for the running interpreter only), then pip resolves the pins in
a dry run (wheels' metadata only, nothing installed). Each macOS target gives pip one tag, the
oldest macOS the plugin says it supports (``plugin/platforms.py`` MAC_MINIMUM): pip accepts wheels
for that version and older, so a wheel that needs a newer macOS fails the check (several tags at
once would only ever test the newest). Usage: python scripts/check_lock.py [PIP] [NAME...]
(a recent pip: 23 or newer; NAMEs: only the targets whose name starts with one of them).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from packaging.requirements import Requirement

PLUGIN = Path(__file__).resolve().parents[1] / "plugin"
LOCK = PLUGIN / "engine-lock.txt"
sys.path.insert(0, str(PLUGIN))
import platforms  # noqa: E402 - the plugin's own statement of the oldest macOS, standard library only

sys.path.remove(str(PLUGIN))
LINUX = [
    "manylinux_2_35_x86_64",
    "manylinux_2_31_x86_64",
    "manylinux_2_28_x86_64",
    "manylinux_2_17_x86_64",
    "manylinux2014_x86_64",
]
TARGETS = {  # name -> (platform tags, python version, marker environment)
    "Linux x86_64 cp311": (LINUX, "3.11", ("linux", "x86_64", "Linux")),
    "Linux x86_64 cp312": (LINUX, "3.12", ("linux", "x86_64", "Linux")),
    "Windows win_amd64 cp312": (["win_amd64"], "3.12", ("win32", "AMD64", "Windows")),
}


def mac_tag(machine: str, version: tuple[int, int]) -> str:
    return f"macosx_{version[0]}_{version[1]}_{machine}"


for _machine, _oldest in platforms.MAC_MINIMUM.items():
    TARGETS[f"macOS {_oldest[0]} {_machine} cp312"] = (
        [mac_tag(_machine, _oldest)],
        "3.12",
        ("darwin", _machine, "Darwin"),
    )


def pins_for(python: str, env3: tuple[str, str, str]) -> list[str]:
    sys_platform, machine, system = env3
    env = {
        "sys_platform": sys_platform,
        "platform_machine": machine,
        "platform_system": system,
        "python_version": python,
        "python_full_version": python + ".0",
        "os_name": "nt" if sys_platform == "win32" else "posix",
        "implementation_name": "cpython",
        "platform_python_implementation": "CPython",
    }
    out = []
    for line in LOCK.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            req = Requirement(line)
            if req.marker is None or req.marker.evaluate(env):
                out.append(f"{req.name}{req.specifier}")
    return out


def check(pip: str, name: str, platforms: list[str], python: str, env3) -> bool:
    with tempfile.TemporaryDirectory() as tmp:
        reqs = Path(tmp) / "reqs.txt"
        reqs.write_text("\n".join(pins_for(python, env3)) + "\n")
        cmd = [pip, "install", "--dry-run", "--quiet", "--no-deps", "--only-binary=:all:", "--ignore-installed"]
        cmd += ["--target", str(Path(tmp) / "t"), "--python-version", python, "-r", str(reqs)]
        for tag in platforms:
            cmd += ["--platform", tag]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    errors = [ln for ln in (run.stdout + run.stderr).splitlines() if "ERROR" in ln]
    print(f"{name}: {'resolves' if run.returncode == 0 else 'FAILS: ' + ' | '.join(errors)}", flush=True)
    return run.returncode == 0


def main(pip: str, only: list[str] | None = None) -> int:
    chosen = {n: t for n, t in TARGETS.items() if not only or n.startswith(tuple(only))}
    results = [check(pip, name, *target) for name, target in chosen.items()]
    return 0 if results and all(results) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "pip", sys.argv[2:]))
