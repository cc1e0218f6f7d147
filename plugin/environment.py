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
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

try:
    from . import child, interpreters, platforms
except ImportError:  # run as a script (scripts/setup.sh: python3 plugin/environment.py install DIR)
    import child  # type: ignore[no-redef]
    import interpreters  # type: ignore[no-redef]
    import platforms  # type: ignore[no-redef]

InstallError, Capabilities, probe = interpreters.InstallError, interpreters.Capabilities, interpreters.probe
child_environ = child.child_environ
PYTHON_VAR, SUPPORTED = interpreters.PYTHON_VAR, interpreters.SUPPORTED
PLUGIN_DIR = Path(__file__).resolve().parents[1]  # holds the engine package soilvolume/
LOCK = Path(__file__).resolve().parent / "engine-lock.txt"
STAMP = "soilvolume-environment.json"
ENV_VAR = "SOILVOLUME_ENGINE_ENV"  # an environment folder to use instead of the profile's
#: every Python the plugin starts: isolated, and UTF-8 on its pipes whatever the system's code page
#: (with -I, PYTHONIOENCODING is not read: a Windows child would write cp1252)
FLAGS = ("-I", "-X", "utf8")
# the engine started in the environment: ``-c BOOT SITE ENGINE_PARENT args...``
BOOT = (
    "import sys,site\n"
    "sites=sys.argv.pop(1)\n"
    "[site.addsitedir(p) for p in sites.split(__import__('os').pathsep) if p]\n"
    "sys.path.insert(0,sys.argv.pop(1))\n"
    "from soilvolume.__main__ import run\n"
    "sys.exit(run())"
)


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
    base: str = ""  # the Python it was built from (a venv's interpreter needs it)

    def command(self, args: Sequence[str]) -> list[str]:
        """The command line that runs ``soilvolume ARGS`` in this environment."""
        flags = [*FLAGS, "-u"] + (["-S"] if self.mode == "target" else [])
        return [self.interpreter, *flags, "-c", BOOT, self.site, str(PLUGIN_DIR), *args]

    def python(self, args: Sequence[str]) -> list[str]:
        """The command line of this environment's Python with ``args`` (isolated, its packages)."""
        if self.mode == "venv":
            return [self.interpreter, *FLAGS, "-u", *args]
        code = f"import site,sys;site.addsitedir({self.site!r});c=sys.argv.pop(1);exec(c)"
        if args[:1] == ["-c"]:
            return [self.interpreter, *FLAGS, "-S", "-u", "-c", code, args[1], *args[2:]]
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
    """``$SOILVOLUME_ENGINE_ENV``, else ``<QGIS profile folder>/soilvolume/engine``; on Windows in
    the local, not the roaming, profile (``%LOCALAPPDATA%``: 800 MB must not roam)."""
    if os.environ.get(ENV_VAR):
        return Path(os.environ[ENV_VAR]).expanduser()
    if settings_dir is None:
        from qgis.core import QgsApplication

        settings_dir = QgsApplication.qgisSettingsDirPath()
    profile = Path(settings_dir)
    roaming, local = os.environ.get("APPDATA"), os.environ.get("LOCALAPPDATA")
    if platforms.is_windows() and roaming and local:
        try:
            profile = Path(local) / profile.relative_to(roaming)
        except ValueError:  # a profile folder chosen elsewhere (--profiles-path): kept there
            pass
    return profile / "soilvolume" / "engine"


def load(folder: Path) -> Environment | None:
    """The environment in ``folder`` if it is complete, made for this lock and version, and the
    Python it was built from is still there (a QGIS update removes the old one)."""
    try:
        data = json.loads((folder / STAMP).read_text(encoding="utf-8"))
        env = Environment(**data)
    except (OSError, ValueError, TypeError):
        return None
    if env.key != lock_key() or not Path(env.interpreter).is_file():
        return None
    if env.base and not Path(env.base).is_file():
        return None
    return env


def status(folder: Path) -> str:
    """ "" when ready, else why not (one sentence)."""
    if load(folder) is not None:
        return ""
    try:
        base = json.loads((folder / STAMP).read_text(encoding="utf-8")).get("base") or ""
    except (OSError, ValueError, AttributeError):
        return "its Python environment is not installed yet"
    if base and not Path(base).is_file():
        return f"the Python its environment was built from is gone ({base}: QGIS was updated?) and must be rebuilt"
    return "its Python environment was made for another version of the plugin and must be updated"


Log = Callable[[str], None]


@dataclass
class Installer:
    """Makes (or updates) the environment in ``folder``; ``log`` gets every line, ``progress``
    0-100, ``cancelled()`` is polled; ``python`` is the Python to build it from ("": the one
    :func:`interpreters.choose` finds); ``caps`` overrides what it is probed to offer (tests)."""

    folder: Path
    log: Log = print
    progress: Callable[[float], None] = lambda _p: None
    cancelled: Callable[[], bool] = lambda: False
    python: str = ""
    caps: Capabilities | None = None
    base: str = ""  # the Python the environment depends on (a venv's base), for its stamp

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
        env = Environment(str(self.folder), mode, interpreter, site, lock_key(), {}, base=self.base)
        self._kernels(env)
        versions = self._selftest(env)
        env = Environment(**{**asdict(env), "versions": versions, "seconds": round(time.perf_counter() - t0, 1)})
        (self.folder / STAMP).write_text(json.dumps(asdict(env), indent=1), encoding="utf-8")
        self.progress(100)
        self.log(
            f"The engine's environment is ready ({self.folder}, {size_mb(self.folder):,.0f} MB, {env.seconds:.0f} s)."
        )
        self.roaming_note()
        return env

    def roaming_note(self) -> None:
        """On Windows, an environment an earlier version left in the roaming profile: said, not
        removed (a QGIS with that version may still use it)."""
        roaming, local = os.environ.get("APPDATA"), os.environ.get("LOCALAPPDATA")
        if not (platforms.is_windows() and roaming and local):
            return
        try:
            old = Path(roaming) / self.folder.relative_to(local)
        except ValueError:
            return
        if (old / STAMP).is_file():
            self.log(
                f"An earlier version's environment is in the roaming profile ({old}, {size_mb(old):,.0f} MB): "
                "delete it once no QGIS with that version uses it"
            )

    def prepare(self) -> tuple[str, str, str, list[str]]:
        """The environment's folder made and its own pip found or bootstrapped (the stamp
        removed: not ready until the self-test passed): (mode, interpreter, site, pip command)."""
        too_old = platforms.mac_too_old()
        if too_old:
            raise InstallError(f"The engine cannot be installed: {too_old}.")
        self.python, source = interpreters.choose(self.python, os.environ.get(PYTHON_VAR, ""))
        caps = self.caps or interpreters.check(self.python, source)
        self.log(f"Building the environment from {self.python} ({source})")
        (self.folder / STAMP).unlink(missing_ok=True)
        self.progress(2)
        mode, interpreter, site = self._create(caps)
        pip = self._pip(mode, interpreter, caps)
        self.progress(10)
        return mode, interpreter, site, pip

    def _quick_check(self, env: Environment) -> bool:
        run = interpreters.run_quiet(env.command(["--help"]), timeout=120)
        return run.returncode == 0

    def _create(self, caps: Capabilities) -> tuple[str, str, str]:
        """A venv; where ``venv`` is missing, fails, or makes a Python that will not start (a
        managed Windows may block programs in the profile), a ``--target`` folder."""
        self.folder.mkdir(parents=True, exist_ok=True)
        if caps.venv:
            try:
                return self._venv()
            except InstallError as exc:
                last = str(exc).strip().splitlines()[-1]
                self.log(f"The venv could not be used ({last}); falling back to a --target folder")
        site, self.base = self.folder / "site-packages", self.python
        site.mkdir(exist_ok=True)
        self.log(f"Packages go to {site}, used with '{self.python} -I -S' (no venv)")
        return "target", self.python, str(site)

    def _venv(self) -> tuple[str, str, str]:
        """The venv, made; remade (``--clear``) when its Python no longer starts (the Python it was
        built from is gone: a QGIS update) or was built from another Python than this one."""
        interpreter = venv_python(self.folder)
        made = (self.folder / "pyvenv.cfg").is_file()
        built_from = interpreters.base_of(interpreter) if made else ""
        if built_from and interpreters.same_file(built_from, interpreters.base_of(self.python) or self.python):
            self.base = built_from
            return "venv", interpreter, ""
        if made:
            why = f"was built from {built_from}" if built_from else f"no longer starts ({interpreter})"
            self.log(f"The environment's Python {why}: rebuilding the venv from {self.python}")
        else:
            self.log(f"Creating the environment (venv) in {self.folder}")
        clear = ["--clear"] if made else []
        self._step([self.python, *FLAGS, "-m", "venv", "--without-pip", *clear, str(self.folder)], "venv")
        self.base = interpreters.base_of(interpreter)
        if not self.base:
            raise InstallError(f"the venv's Python does not start ({interpreter})")
        return "venv", interpreter, ""

    def _pip(self, mode: str, interpreter: str, caps: Capabilities) -> list[str]:
        """The pip command for the environment: its own pip (from ensurepip or PyPI's wheel)."""
        pip = [interpreter, *FLAGS, "-m", "pip"]
        if mode == "venv":
            if interpreters.run_quiet([*pip, "--version"], timeout=120).returncode == 0:
                return pip
            if caps.ensurepip:
                self.log("Adding pip to the environment (ensurepip)")
                ensure = [interpreter, *FLAGS, "-m", "ensurepip", "--default-pip"]
                if interpreters.run_quiet(ensure, timeout=300).returncode == 0:
                    return pip
            wheel = interpreters.pip_wheel(self.folder, self.log)
            self._step([interpreter, *FLAGS, str(wheel / "pip"), "install", "--no-index", str(wheel)], "pip")
            return pip
        if caps.pip:
            return pip
        return [interpreter, *FLAGS, str(interpreters.pip_wheel(self.folder, self.log) / "pip")]

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

        try:
            self._step(command, "pip", advance)
        except InstallError as exc:
            raise InstallError(platforms.no_wheel(str(exc)) or str(exc)) from None

    def _kernels(self, env: Environment) -> None:
        """The engine's native kernels built with the machine's C compiler, when it has one (beside
        their source in the plugin's engine package; said only when built now or not built);
        without, the engine runs its numpy path: the same results, slower. On macOS without the
        command-line tools nothing is tried (``/usr/bin/cc`` would pop Apple's install dialog)."""
        if not platforms.has_compiler_tools():
            self.log(
                "Native kernels: not built (no C compiler: macOS's command-line developer tools are not "
                "installed; 'xcode-select --install' adds them); the engine runs without them, slower"
            )
            return
        code = "import sys;sys.path.insert(0,sys.argv[1]);from soilvolume.native.build import main;sys.exit(main([]))"
        run = interpreters.run_quiet(env.python(["-c", code, str(PLUGIN_DIR)]), timeout=300)
        said = interpreters.tail(run.stdout + run.stderr, 2)
        if run.returncode != 0:
            self.log(f"Native kernels: not built ({said}); the engine runs without them, slower")
        elif "built:" in said:
            self.log("Native kernels: built (the engine's faster path)")

    def _selftest(self, env: Environment) -> dict:
        self.log("Testing the engine in its environment (imports, a spawned Dask worker, a tiny seeded estimate)")
        self.progress(85)
        with scratch("soilvolume-selftest-") as tmp:
            out = self._step(env.command(["selftest", "--out", str(tmp / "run"), "--progress", "jsonl"]), "engine")
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


@contextmanager
def scratch(prefix: str) -> Iterator[Path]:
    """A temporary folder, removed after as far as it can be: on Windows a file a child still
    holds (an antivirus scan, a worker closing) raises PermissionError, which must not fail an
    install that succeeded."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


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
    """A venv's interpreter: where ``venv`` of the running system puts it (never a simulated one's)."""
    return str(folder / ("Scripts/python.exe" if sys.platform == "win32" else "bin/python"))


def size_mb(folder: Path) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


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
