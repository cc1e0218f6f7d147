"""Which system the plugin runs on, in one place: every Windows- or macOS-specific decision of the
installer and of the child processes asks this module, so tests can set ``SYSTEM``, ``MACHINE``
and ``MAC_VERSION`` and run those paths on Linux. Standard library only.
"""

from __future__ import annotations

import platform
import shutil
import subprocess
import sys

#: "windows", "macos" or "linux" (any other POSIX); None: the running system's
SYSTEM: str | None = None
#: "x86_64"/"AMD64", "arm64"/"aarch64", ...; None: the running machine's
MACHINE: str | None = None
#: "14.5"; None: the running Mac's (``platform.mac_ver``), "" off macOS
MAC_VERSION: str | None = None
#: the oldest macOS the pinned wheels support, per machine (pyproj 3.7 and rasterio 1.4 set it)
MAC_MINIMUM = {"arm64": (14, 0), "x86_64": (13, 0)}
MAC_NAMES = {(13, 0): "macOS 13 (Ventura)", (14, 0): "macOS 14 (Sonoma)"}


def system() -> str:
    if SYSTEM is not None:
        return SYSTEM
    if sys.platform == "win32":
        return "windows"
    return "macos" if sys.platform == "darwin" else "linux"


def is_windows() -> bool:
    return system() == "windows"


def is_macos() -> bool:
    return system() == "macos"


def machine() -> str:
    """The machine as wheels name it on macOS (arm64, x86_64), else as the system says."""
    name = MACHINE if MACHINE is not None else platform.machine()
    return {"aarch64": "arm64", "AMD64": "x86_64", "amd64": "x86_64"}.get(name, name) if is_macos() else name


def mac_version() -> tuple[int, ...]:
    """The running macOS as numbers, () when unknown or not macOS."""
    text = MAC_VERSION if MAC_VERSION is not None else (platform.mac_ver()[0] if sys.platform == "darwin" else "")
    try:
        return tuple(int(p) for p in text.split(".") if p)
    except ValueError:
        return ()


def mac_too_old() -> str:
    """On a macOS older than the pinned wheels support, the sentence that says so; else ""."""
    if not is_macos():
        return ""
    version, minimum = mac_version(), MAC_MINIMUM.get(machine())
    if not version or minimum is None or version >= minimum:
        return ""
    shown = ".".join(map(str, version))
    return f"this Mac runs macOS {shown}; the engine's packages (pyproj, rasterio) need {mac_needs()}"


def mac_needs() -> str:
    """The macOS versions the pinned wheels need, as a sentence's part."""
    chips = {"arm64": "Apple silicon", "x86_64": "Intel"}
    return ", ".join(f"{MAC_NAMES[v]} or later on {chips[m]}" for m, v in MAC_MINIMUM.items())


def no_wheel(pip_error: str) -> str:
    """pip's "No matching distribution" as a sentence about this system ("" for other errors)."""
    if "No matching distribution found for" not in pip_error:
        return ""
    name = pip_error.split("No matching distribution found for", 1)[1].split()[0]
    here = f"{system()} {machine()}"
    return (
        f"pip found no wheel of {name} for this system ({here}); the engine's packages support Windows 10/11 "
        f"x86-64, Linux x86-64 and macOS ({mac_needs()}), with Python 3.11 or 3.12"
    )


def has_compiler_tools() -> bool:
    """Whether a C compiler can be run without a system dialog: on macOS ``/usr/bin/cc`` is a
    shim that asks to install the command-line tools unless ``xcode-select -p`` finds them."""
    if not is_macos():
        return True
    tool = shutil.which("xcode-select")
    if tool is None:
        return False
    try:
        return subprocess.run([tool, "-p"], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False
