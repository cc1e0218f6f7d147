"""The Python the engine's environment is built from: the one given (the install algorithm's
parameter, kept in QGIS's settings, or ``$SOILVOLUME_PYTHON``), else QGIS's own found beside QGIS
(its layout on Windows, macOS and Linux); never whatever ``python3`` is first on the PATH (Apple's
3.9 or its "install developer tools" dialog on macOS, the Store's alias on Windows). A wrong one
is refused in one line that says how to choose another. Standard library only.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import urllib.parse
import urllib.request
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

try:
    from . import child, platforms
except ImportError:  # run as a script (scripts/setup.sh: python3 plugin/environment.py install DIR)
    import child  # type: ignore[no-redef]
    import platforms  # type: ignore[no-redef]

PYTHON_VAR = "SOILVOLUME_PYTHON"  # a Python 3.11/3.12 to build it from instead of QGIS's
SUPPORTED = ((3, 11), (3, 12))
PIP_JSON = "https://pypi.org/pypi/pip/json"
#: the ways to choose the Python, for the messages (QGIS started from Finder or the Start menu
#: sees no shell variables: its own Options set them)
HOW_TO_CHOOSE = (
    "choose a Python 3.11 or 3.12 (e.g. from python.org) as the 'Python to build the environment from' "
    "parameter of Processing Toolbox > Soil volume change > Set-up > Install dependencies, or set the "
    f"variable {PYTHON_VAR} in Settings > Options > System > Environment (on macOS: QGIS > Preferences…)"
)
PROBE = (
    "import importlib.util as u,json,sys;"
    "print(json.dumps([sys.version_info[:2],*[u.find_spec(m) is not None for m in ('venv','ensurepip','pip')]]))"
)


class InstallError(Exception):
    """The environment could not be made; the message ends with the tool's last lines."""


@dataclass(frozen=True)
class Capabilities:
    """What the base interpreter offers (each may be missing on a stock QGIS)."""

    version: tuple[int, int]
    venv: bool
    ensurepip: bool
    pip: bool


def layout(prefix: Path, version: tuple[int, int]) -> list[Path]:
    """Where a Python's interpreter lies under its prefix on this system."""
    if platforms.is_windows():  # the QGIS installer and OSGeo4W: apps\\Python312\\python.exe
        return [prefix / "python.exe", prefix / "python3.exe"]
    major, minor = version
    return [prefix / "bin" / f"python{major}.{minor}", prefix / "bin" / "python3"]


def qgis_python(executable: str, prefixes: Iterable[str], version: tuple[int, int]) -> str:
    """QGIS's own Python, beside QGIS: ``executable`` itself when it is a Python inside one of the
    ``prefixes`` (in embedded Python it is often the QGIS binary), else the interpreter of the
    prefixes' layout (on macOS also ``QGIS.app/Contents/MacOS/bin/python3``); "" when none is."""
    exe, roots = Path(executable or ""), [Path(p) for p in prefixes if p]
    if exe.name.lower().startswith("python") and any(r in exe.parents for r in roots):
        return str(exe)
    candidates = [c for r in roots for c in layout(r, version)]
    if platforms.is_macos() and exe.name:
        candidates += layout(exe.parent, version)
    return next((str(c) for c in candidates if c.is_file()), "")


def choose(given: str = "", variable: str = "") -> tuple[str, str]:
    """(interpreter, what chose it): ``given``, else ``variable`` ($SOILVOLUME_PYTHON), else
    QGIS's own; InstallError when QGIS's own is not found."""
    if given:
        return given, "the Python given to the installer"
    if variable:
        return variable, PYTHON_VAR
    prefixes = (sys.base_exec_prefix, sys.exec_prefix, sys.base_prefix, sys.prefix)
    found = qgis_python(sys.executable, prefixes, sys.version_info[:2])
    if not found:
        raise InstallError(f"QGIS's own Python was not found beside QGIS ({sys.executable}); {HOW_TO_CHOOSE}")
    return found, "QGIS's own Python"


def probe(python: str) -> Capabilities:
    run = run_quiet([python, "-I", "-X", "utf8", "-c", PROBE], timeout=60)
    if run.returncode != 0:
        raise InstallError(f"{python} does not run: {tail(run.stdout + run.stderr)}")
    version, venv, ensurepip, pip = json.loads(run.stdout.strip().splitlines()[-1])
    return Capabilities(tuple(version), venv, ensurepip, pip)


def check(python: str, source: str) -> Capabilities:
    """What ``python`` offers, or InstallError in one line naming it, ``source`` and the fix."""
    if not Path(python).is_file():
        raise InstallError(f"{python} ({source}): no such file; {HOW_TO_CHOOSE}")
    if platforms.is_macos() and Path(python).parent == Path("/usr/bin") and not platforms.has_compiler_tools():
        raise InstallError(f"{python} ({source}) is Apple's placeholder for its developer tools; {HOW_TO_CHOOSE}")
    try:
        caps = probe(python)
    except (InstallError, ValueError, TypeError) as exc:
        last = str(exc).strip().splitlines()[-1] if str(exc).strip() else "no answer"
        raise InstallError(f"{python} ({source}) does not run as a Python ({last}); {HOW_TO_CHOOSE}") from None
    if not SUPPORTED[0] <= tuple(caps.version) <= SUPPORTED[-1]:
        shown = ".".join(map(str, caps.version))
        raise InstallError(f"{python} ({source}) is Python {shown}; the engine needs 3.11 or 3.12: {HOW_TO_CHOOSE}")
    return caps


def pip_wheel(folder: Path, log) -> Path:
    """PyPI's pure-Python pip wheel in ``folder``/.bootstrap (checked against its SHA-256), for a
    Python without pip."""
    log(f"This Python has no pip: downloading pip's wheel from PyPI ({PIP_JSON})")
    with urllib.request.urlopen(PIP_JSON, timeout=60) as answer:  # noqa: S310 - a fixed https URL
        release = json.load(answer)
    wheel = next(u for u in release["urls"] if u["filename"].endswith("py3-none-any.whl"))
    target = folder / ".bootstrap" / wheel["filename"]
    target.parent.mkdir(parents=True, exist_ok=True)
    url = urllib.parse.urljoin(PIP_JSON, wheel["url"])  # mirrors answer with relative links
    with urllib.request.urlopen(url, timeout=120) as answer:  # noqa: S310
        data = answer.read()
    if hashlib.sha256(data).hexdigest() != wheel["digests"]["sha256"]:
        raise InstallError(f"pip's wheel from PyPI does not match its SHA-256 ({wheel['filename']})")
    target.write_bytes(data)
    return target


def starts(python: str) -> bool:
    """Whether ``python`` starts (a venv whose base Python was removed does not)."""
    return bool(base_of(python))


def base_of(python: str) -> str:
    """The Python a venv's ``python`` runs on (itself for any other Python); "" when it does not start."""
    code = "import sys;print(getattr(sys,'_base_executable','') or sys.executable)"
    run = run_quiet([python, "-I", "-c", code], timeout=60) if Path(python).is_file() else None
    return run.stdout.strip().splitlines()[-1] if run and run.returncode == 0 and run.stdout.strip() else ""


def same_file(a: str, b: str) -> bool:
    """Whether two paths name one file (through links)."""
    return os.path.normcase(os.path.realpath(a)) == os.path.normcase(os.path.realpath(b))


def run_quiet(command: list[str], timeout: float) -> subprocess.CompletedProcess:
    """``command`` with its output captured (UTF-8), QGIS's variables scrubbed, no console."""
    try:
        return subprocess.run(
            command,
            capture_output=True,
            text=True,
            encoding="utf-8",
            errors="replace",
            timeout=timeout,
            env=child.child_environ(),
            stdin=subprocess.DEVNULL,
            **child.detached(),
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return subprocess.CompletedProcess(command, 1, "", str(exc))


def tail(text: str, n: int = 8) -> str:
    return "\n".join(text.strip().splitlines()[-n:])
