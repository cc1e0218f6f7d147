"""The engine's own Python environment: where it is, how the engine starts in it, and its installer.

The engine never runs inside QGIS's Python: every algorithm starts it as a subprocess in an
environment of the plugin's own that holds exactly the pins of ``engine-lock.txt`` (its own numpy,
pyproj, rasterio, Open3D, ...), isolated from QGIS's packages and libraries. The environment is a
venv (``python -m venv --without-pip``; pip from ``ensurepip`` or, where QGIS's Python has none,
from PyPI's pip wheel), or, where ``venv`` itself is missing, a pip ``--target`` folder used by
QGIS's interpreter started with ``-I -S`` (no site-packages of QGIS or of the system).

Standard library only, no QGIS: ``scripts/setup.sh`` runs this file to build the tests'
environment with the same code (``python3 plugin/environment.py install DIR``).
"""

from __future__ import annotations

import configparser
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

try:
    from . import child
except ImportError:  # run as a script (scripts/setup.sh: python3 plugin/environment.py install DIR)
    import child  # type: ignore[no-redef]

PLUGIN_DIR = Path(__file__).resolve().parents[1]  # holds the engine package soilvolume/
LOCK = Path(__file__).resolve().parent / "engine-lock.txt"
STAMP = "soilvolume-environment.json"
ENV_VAR = "SOILVOLUME_ENGINE_ENV"  # an environment folder to use instead of the profile's
PYTHON_VAR = "SOILVOLUME_PYTHON"  # a Python 3.11/3.12 to build it from instead of QGIS's
SUPPORTED = ((3, 11), (3, 12))
PIP_JSON = "https://pypi.org/pypi/pip/json"
# variables of QGIS's process a child must not inherit (OSGeo4W and the macOS bundle set several)
SCRUBBED_PREFIXES = ("PYTHON", "QT_", "QGIS_", "DYLD_", "CONDA_PYTHON")
SCRUBBED = {"PROJ_LIB", "PROJ_DATA", "PROJ_NETWORK", "GDAL_DATA", "GDAL_DRIVER_PATH", "GDAL_PLUGINS", "VIRTUAL_ENV"}
# the engine started in the environment: ``-c BOOT SITE ENGINE_PARENT args...``
BOOT = (
    "import sys,site\n"
    "sites=sys.argv.pop(1)\n"
    "[site.addsitedir(p) for p in sites.split(__import__('os').pathsep) if p]\n"
    "sys.path.insert(0,sys.argv.pop(1))\n"
    "from soilvolume.__main__ import run\n"
    "sys.exit(run())"
)


class InstallError(Exception):
    """The environment could not be made; the message ends with the tool's last lines."""


@dataclass(frozen=True)
class Environment:
    """A ready environment (as its stamp records it)."""

    folder: str
    mode: str  # "venv" or "target"
    interpreter: str  # the Python that runs the engine
    site: str  # the --target folder ("" for a venv)
    key: str  # lock + plugin version it was made for
    versions: dict
    seconds: float = 0.0

    def command(self, args: Sequence[str]) -> list[str]:
        """The command line that runs ``soilvolume ARGS`` in this environment."""
        flags = ["-I", "-u"] + (["-S"] if self.mode == "target" else [])
        return [self.interpreter, *flags, "-c", BOOT, self.site, str(PLUGIN_DIR), *args]

    def python(self, args: Sequence[str]) -> list[str]:
        """The command line of this environment's Python with ``args`` (isolated, its packages)."""
        if self.mode == "venv":
            return [self.interpreter, "-I", "-u", *args]
        code = f"import site,sys;site.addsitedir({self.site!r});c=sys.argv.pop(1);exec(c)"
        if args[:1] == ["-c"]:
            return [self.interpreter, "-I", "-S", "-u", "-c", code, args[1], *args[2:]]
        raise ValueError("only -c CODE is supported in a --target environment")


def plugin_version() -> str:
    parser = configparser.ConfigParser()
    parser.read(PLUGIN_DIR / "metadata.txt", encoding="utf-8")
    return parser.get("general", "version", fallback="unknown")


def lock_key() -> str:
    """What an environment is made for: the lock file and the plugin version."""
    digest = hashlib.sha256(LOCK.read_bytes())
    digest.update(plugin_version().encode())
    return digest.hexdigest()[:16]


def env_folder(settings_dir: str | Path | None = None) -> Path:
    """``$SOILVOLUME_ENGINE_ENV``, else ``<QGIS profile folder>/soilvolume/engine``."""
    if os.environ.get(ENV_VAR):
        return Path(os.environ[ENV_VAR]).expanduser()
    if settings_dir is None:
        from qgis.core import QgsApplication

        settings_dir = QgsApplication.qgisSettingsDirPath()
    return Path(settings_dir) / "soilvolume" / "engine"


def load(folder: Path) -> Environment | None:
    """The environment in ``folder`` if it is complete and made for this lock and version."""
    try:
        data = json.loads((folder / STAMP).read_text(encoding="utf-8"))
        env = Environment(**data)
    except (OSError, ValueError, TypeError):
        return None
    if env.key != lock_key() or not Path(env.interpreter).is_file():
        return None
    return env


def status(folder: Path) -> str:
    """ "" when ready, else why not (one sentence)."""
    if load(folder) is not None:
        return ""
    if (folder / STAMP).is_file():
        return "its Python environment was made for another version of the plugin and must be updated"
    return "its Python environment is not installed yet"


def child_environ(extra: dict[str, str] | None = None) -> dict[str, str]:
    """QGIS's environment without what would steer the child's Python or libraries."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in SCRUBBED and not k.upper().startswith(SCRUBBED_PREFIXES) and not k.startswith("LD_PRELOAD")
    }
    env["PYTHONIOENCODING"] = "utf-8"  # read only without -I; harmless with it
    env.update(extra or {})
    return env


def base_python() -> str:
    """The interpreter the environment is built from: ``$SOILVOLUME_PYTHON``, else QGIS's own
    (in embedded Python ``sys.executable`` is often the QGIS binary)."""
    if os.environ.get(PYTHON_VAR):
        return os.environ[PYTHON_VAR]
    exe = Path(sys.executable or "")
    prefixes = {Path(sys.prefix), Path(sys.exec_prefix), Path(sys.base_prefix)}
    if exe.name.lower().startswith("python") and any(p in exe.parents for p in prefixes):
        return str(exe)
    prefix, v = Path(sys.base_exec_prefix), sys.version_info
    if sys.platform == "win32":
        candidates = [prefix / "python.exe", prefix / "python3.exe"]
    else:
        candidates = [prefix / "bin" / f"python{v.major}.{v.minor}", prefix / "bin" / "python3"]
    found = next((c for c in candidates if c.is_file()), None)
    return str(found) if found else shutil.which("python3") or "python3"


@dataclass(frozen=True)
class Capabilities:
    """What the base interpreter offers (each may be missing on a stock QGIS)."""

    version: tuple[int, int]
    venv: bool
    ensurepip: bool
    pip: bool


PROBE = (
    "import importlib.util as u,json,sys;"
    "print(json.dumps([sys.version_info[:2],*[u.find_spec(m) is not None for m in ('venv','ensurepip','pip')]]))"
)


def probe(python: str) -> Capabilities:
    run = _run([python, "-I", "-c", PROBE], timeout=60)
    if run.returncode != 0:
        raise InstallError(f"{python} does not run: {_tail(run.stdout + run.stderr)}")
    version, venv, ensurepip, pip = json.loads(run.stdout.strip().splitlines()[-1])
    return Capabilities(tuple(version), venv, ensurepip, pip)


Log = Callable[[str], None]


@dataclass
class Installer:
    """Makes (or updates) the environment in ``folder``; ``log`` gets every line, ``progress``
    0-100, ``cancelled()`` is polled; ``caps`` overrides what the base Python is probed to offer
    (tests of the fallbacks)."""

    folder: Path
    log: Log = print
    progress: Callable[[float], None] = lambda _p: None
    cancelled: Callable[[], bool] = lambda: False
    python: str = ""
    caps: Capabilities | None = None

    def run(self, force: bool = False) -> Environment:
        t0 = time.perf_counter()
        existing = None if force else load(self.folder)
        if existing is not None and self._quick_check(existing):
            self._kernels(existing)
            self.log(f"The engine's environment is ready ({self.folder}); nothing to do.")
            self.progress(100)
            return existing
        mode, interpreter, site, pip = self.prepare()
        self._install(pip, site)
        env = Environment(str(self.folder), mode, interpreter, site, lock_key(), {})
        self._kernels(env)
        versions = self._selftest(env)
        env = Environment(**{**asdict(env), "versions": versions, "seconds": round(time.perf_counter() - t0, 1)})
        (self.folder / STAMP).write_text(json.dumps(asdict(env), indent=1), encoding="utf-8")
        self.progress(100)
        self.log(
            f"The engine's environment is ready ({self.folder}, {size_mb(self.folder):,.0f} MB, {env.seconds:.0f} s)."
        )
        return env

    def prepare(self) -> tuple[str, str, str, list[str]]:
        """The environment's folder made and its own pip found or bootstrapped (the stamp
        removed: not ready until the self-test passed): (mode, interpreter, site, pip command)."""
        self.python = self.python or base_python()
        caps = self.caps or probe(self.python)
        if not SUPPORTED[0] <= tuple(caps.version) <= SUPPORTED[-1]:
            raise InstallError(
                f"{self.python} is Python {'.'.join(map(str, caps.version))}; the engine's environment needs "
                f"Python 3.11 or 3.12. Install one and set the environment variable {PYTHON_VAR} to it."
            )
        (self.folder / STAMP).unlink(missing_ok=True)
        self.progress(2)
        mode, interpreter, site = self._create(caps)
        pip = self._pip(mode, interpreter, caps)
        self.progress(10)
        return mode, interpreter, site, pip

    def _quick_check(self, env: Environment) -> bool:
        run = _run(env.command(["--help"]), timeout=120)
        return run.returncode == 0

    def _create(self, caps: Capabilities) -> tuple[str, str, str]:
        self.folder.mkdir(parents=True, exist_ok=True)
        if caps.venv:
            interpreter = venv_python(self.folder)
            if not Path(interpreter).is_file():
                self.log(f"Creating the environment (venv) in {self.folder}")
                self._step([self.python, "-I", "-m", "venv", "--without-pip", str(self.folder)], "venv")
            return "venv", interpreter, ""
        site = self.folder / "site-packages"
        site.mkdir(exist_ok=True)
        self.log(f"This Python has no venv module: packages go to {site}, used with 'python -I -S'")
        return "target", self.python, str(site)

    def _pip(self, mode: str, interpreter: str, caps: Capabilities) -> list[str]:
        """The pip command for the environment: its own pip (from ensurepip or PyPI's wheel)."""
        if mode == "venv":
            if _run([interpreter, "-I", "-m", "pip", "--version"], timeout=120).returncode == 0:
                return [interpreter, "-I", "-m", "pip"]
            if caps.ensurepip:
                self.log("Adding pip to the environment (ensurepip)")
                if _run([interpreter, "-I", "-m", "ensurepip", "--default-pip"], timeout=300).returncode == 0:
                    return [interpreter, "-I", "-m", "pip"]
            wheel = self._pip_wheel()
            self._step([interpreter, "-I", str(wheel / "pip"), "install", "--no-index", str(wheel)], "pip")
            return [interpreter, "-I", "-m", "pip"]
        if caps.pip:
            return [interpreter, "-I", "-m", "pip"]
        return [interpreter, "-I", str(self._pip_wheel() / "pip")]

    def _pip_wheel(self) -> Path:
        """PyPI's pure-Python pip wheel (checked against its SHA-256), for a Python without pip."""
        self.log(f"This Python has no pip: downloading pip's wheel from PyPI ({PIP_JSON})")
        with urllib.request.urlopen(PIP_JSON, timeout=60) as answer:  # noqa: S310 - a fixed https URL
            release = json.load(answer)
        wheel = next(u for u in release["urls"] if u["filename"].endswith("py3-none-any.whl"))
        target = self.folder / ".bootstrap" / wheel["filename"]
        target.parent.mkdir(parents=True, exist_ok=True)
        url = urllib.parse.urljoin(PIP_JSON, wheel["url"])  # mirrors answer with relative links
        with urllib.request.urlopen(url, timeout=120) as answer:  # noqa: S310
            data = answer.read()
        if hashlib.sha256(data).hexdigest() != wheel["digests"]["sha256"]:
            raise InstallError(f"pip's wheel from PyPI does not match its SHA-256 ({wheel['filename']})")
        target.write_bytes(data)
        return target

    def _install(self, pip: list[str], site: str) -> None:
        count = sum(1 for line in LOCK.read_text().splitlines() if line.strip() and not line.startswith("#"))
        self.log(f"Installing the engine's {count} pinned packages ({LOCK.name})")
        command = [*pip, "install", "--disable-pip-version-check", "--no-input", "--no-deps"]
        command += ["--only-binary=:all:", "-r", str(LOCK)]
        if site:
            command += ["--target", site, "--upgrade"]
        seen = [0]

        def advance(line: str) -> None:
            if line.startswith(("Collecting", "Installing", "Successfully", "Requirement already")):
                seen[0] += 1
                self.progress(10 + 70 * min(1.0, seen[0] / (count + 2)))

        self._step(command, "pip", advance)

    def _kernels(self, env: Environment) -> None:
        """The engine's native kernels built with the machine's C compiler, when it has one (beside
        their source in the plugin's engine package; said only when built now or not built);
        without, the engine runs its numpy path: the same results, slower."""
        code = "import sys;sys.path.insert(0,sys.argv[1]);from soilvolume.native.build import main;sys.exit(main([]))"
        run = _run(env.python(["-c", code, str(PLUGIN_DIR)]), timeout=300)
        said = _tail(run.stdout + run.stderr, 2)
        if run.returncode != 0:
            self.log(f"Native kernels: not built ({said}); the engine runs without them, slower")
        elif "built:" in said:
            self.log("Native kernels: built (the engine's faster path)")

    def _selftest(self, env: Environment) -> dict:
        self.log("Testing the engine in its environment (imports, then a tiny seeded estimate)")
        self.progress(85)
        with tempfile.TemporaryDirectory(prefix="soilvolume-selftest-") as tmp:
            out = self._step(
                env.command(["selftest", "--out", str(Path(tmp) / "run"), "--progress", "jsonl"]), "engine"
            )
        for line in reversed(out):
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if event.get("type") == "result":
                self.log(f"Self-test passed: net {event['net_m3']:+.1f} m³ (true {event['true_net_m3']:+.1f} m³)")
                return event.get("versions") or {}
        raise InstallError("the engine's self-test gave no result:\n" + "\n".join(out[-12:]))

    def _step(self, command: list[str], tool: str, each: Callable[[str], None] | None = None) -> list[str]:
        """Run one tool, every line to the log; InstallError with its last lines if it fails."""
        self.log("Running: " + " ".join(f'"{a}"' if " " in a else a for a in command if "\n" not in a))
        proc = child.start(command, child_environ())
        proc.stdin.close()
        kept: deque[str] = deque(maxlen=400)
        try:
            for _stream, line in child.lines(proc, self.cancelled):
                kept.append(line)
                if not line.startswith("{"):
                    self.log(line)
                if each is not None:
                    each(line)
        except child.Cancelled:
            raise InstallError("cancelled; run the installer again to finish the environment") from None
        code = child.exit_code(proc)
        if code != 0:
            raise InstallError(f"{tool} failed (exit {code}); its last lines:\n" + "\n".join(_readable(kept)[-12:]))
        return list(kept)


def _readable(lines) -> list[str]:
    """Protocol lines as their messages (the engine's errors), other lines as they are."""
    out = []
    for line in lines:
        try:
            event = json.loads(line)
            out.append(event.get("message") or line) if isinstance(event, dict) else out.append(line)
        except ValueError:
            out.append(line)
    return out


def venv_python(folder: Path) -> str:
    return str(folder / ("Scripts/python.exe" if sys.platform == "win32" else "bin/python"))


def size_mb(folder: Path) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


def _run(command: list[str], timeout: float) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(
            command,
            capture_output=True,
            text=True,
            encoding="utf-8",
            errors="replace",
            timeout=timeout,
            env=child_environ(),
            stdin=subprocess.DEVNULL,
            **child.detached(),
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return subprocess.CompletedProcess(command, 1, "", str(exc))


def _tail(text: str, n: int = 8) -> str:
    return "\n".join(text.strip().splitlines()[-n:])


def main(argv: list[str]) -> int:
    """``python3 plugin/environment.py install DIR [--force]``: build an environment headless."""
    if len(argv) < 2 or argv[0] != "install":
        print("usage: environment.py install DIR [--force]", file=sys.stderr)
        return 2
    try:
        Installer(Path(argv[1]).resolve()).run(force="--force" in argv)
    except InstallError as exc:
        print(f"environment: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
