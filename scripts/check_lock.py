"""Does plugin/engine-lock.txt resolve to wheels on every platform QGIS users have?

For each target (platform tags, Python version) the lock's environment markers are evaluated for
that target (pip evaluates them for the running interpreter only), then pip resolves the pins in
a dry run (wheels' metadata only, nothing installed). Usage: python scripts/check_lock.py [PIP]
(a recent pip: 23 or newer).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from packaging.requirements import Requirement

LOCK = Path(__file__).resolve().parents[1] / "plugin" / "engine-lock.txt"
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
    "macOS arm64 cp312": ([f"macosx_{v}_0_arm64" for v in (14, 13, 12, 11)], "3.12", ("darwin", "arm64", "Darwin")),
    "macOS x86_64 cp312": (
        [f"macosx_{v}_0_x86_64" for v in (14, 13, 12, 11)] + ["macosx_10_15_x86_64", "macosx_10_9_x86_64"],
        "3.12",
        ("darwin", "x86_64", "Darwin"),
    ),
}


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


def main(pip: str) -> int:
    results = [check(pip, name, *target) for name, target in TARGETS.items()]
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "pip"))
