"""Running a child process from QGIS: its output lines as they come, cancellation within a
second, and the engine's ``--progress jsonl`` protocol read into callbacks.

Every wait has a timeout or a cancel check: the pipes are read by threads into a queue that is
polled every 0.1 s. Standard library only.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

try:
    from . import platforms
except ImportError:  # run as a script (scripts/setup.sh: python3 plugin/environment.py install DIR)
    import platforms  # type: ignore[no-redef]

POLL_S = 0.1
GRACE_S = 0.3  # after "cancel" on stdin, then after SIGTERM, before the next, harder stop
EXIT_S = 30.0  # how long a child that closed its output may take to exit
# variables of QGIS's process a child must not inherit (OSGeo4W and the macOS bundle set several)
SCRUBBED_PREFIXES = ("PYTHON", "QT_", "QGIS_", "DYLD_", "CONDA_PYTHON")
SCRUBBED = {"PROJ_LIB", "PROJ_DATA", "PROJ_NETWORK", "GDAL_DATA", "GDAL_DRIVER_PATH", "GDAL_PLUGINS", "VIRTUAL_ENV"}
#: Windows' status codes of a crash (NTSTATUS), shown in hex as Windows documents them
WINDOWS_CRASHES = {
    0xC0000005: "access violation",
    0xC0000409: "stack buffer overrun",
    0xC00000FD: "stack overflow",
    0xC0000135: "a DLL was not found",
    0xC0000139: "a DLL entry point was not found",
    0xC000001D: "illegal instruction",
    0xC0000017: "out of memory",
    0xC000013A: "stopped by Ctrl+C or a closed console",
}


def child_environ(extra: dict[str, str] | None = None) -> dict[str, str]:
    """QGIS's environment without what would steer the child's Python or libraries."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in SCRUBBED and not k.upper().startswith(SCRUBBED_PREFIXES) and not k.startswith("LD_PRELOAD")
    }
    env["PYTHONIOENCODING"] = "utf-8"  # read only without -I (children run with -X utf8 besides)
    env.update(extra or {})
    return env


ERROR_PREFIX = "soilvolume: error:"  # the engine's own error line on its standard error


class Cancelled(Exception):
    """The user cancelled; the child was stopped."""


def detached() -> dict:
    """Popen arguments that put a child in a process group of its own (a stop reaches its
    workers too), out of QGIS's console and signals (the real system's: never a simulated one)."""
    if sys.platform == "win32":
        return {"creationflags": 0x08000000 | 0x00000200}  # CREATE_NO_WINDOW | CREATE_NEW_PROCESS_GROUP
    return {"start_new_session": True}


def start(command: Sequence[str], env: dict[str, str], cwd: str | None = None) -> subprocess.Popen:
    """The child, detached (:func:`detached`), its pipes in text."""
    return subprocess.Popen(
        list(command),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
        errors="replace",
        bufsize=1,
        env=env,
        cwd=cwd,
        **detached(),
    )


def stop(proc: subprocess.Popen) -> None:
    """Ask the child to cancel ("cancel" on stdin), then SIGTERM its group, then kill it."""
    try:
        if proc.stdin is not None:
            proc.stdin.write("cancel\n")
            proc.stdin.flush()
    except (OSError, ValueError):
        pass
    for hard in (False, True):
        try:
            proc.wait(timeout=GRACE_S)
            return
        except subprocess.TimeoutExpired:
            _signal(proc, hard)
    proc.wait(timeout=10)


def exit_code(proc: subprocess.Popen, timeout: float = EXIT_S) -> int:
    """The child's exit status once it closed its output; stopped (:func:`stop`) when it does
    not exit within ``timeout`` (its status is then the signal's)."""
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        stop(proc)
        return proc.returncode


def _signal(proc: subprocess.Popen, hard: bool) -> None:
    """SIGTERM (then SIGKILL) to the child's process group; on Windows the child's process tree
    ends at once (``taskkill /T /F``: Dask workers included), else the child alone."""
    try:
        if sys.platform != "win32":
            os.killpg(proc.pid, signal.SIGKILL if hard else signal.SIGTERM)
        elif not _kill_tree(proc):
            proc.kill()
    except (ProcessLookupError, PermissionError, OSError):
        pass


def _kill_tree(proc: subprocess.Popen) -> bool:
    try:
        command = ["taskkill", "/T", "/F", "/PID", str(proc.pid)]
        return subprocess.run(command, capture_output=True, timeout=10, **detached()).returncode == 0
    except (OSError, ValueError, subprocess.TimeoutExpired):
        return False


def lines(proc: subprocess.Popen, cancelled: Callable[[], bool]) -> Iterator[tuple[str, str]]:
    """("out" | "err", line) as the child writes them, until both pipes close; on
    ``cancelled()`` the child is stopped and :class:`Cancelled` raised."""
    q: queue.Queue = queue.Queue()

    def pump(name: str, pipe) -> None:
        try:
            for line in pipe:
                q.put((name, line.rstrip("\r\n")))
        except (OSError, ValueError):
            pass
        q.put((name, None))

    readers = [
        threading.Thread(target=pump, args=(n, p), daemon=True) for n, p in (("out", proc.stdout), ("err", proc.stderr))
    ]
    for reader in readers:
        reader.start()
    open_pipes = 2
    while open_pipes:
        if cancelled():
            stop(proc)
            _close(proc, readers)
            raise Cancelled()
        try:
            name, line = q.get(timeout=POLL_S)
        except queue.Empty:
            continue
        if line is None:
            open_pipes -= 1
        else:
            yield name, line
    _close(proc, readers)


def _close(proc: subprocess.Popen, readers: list[threading.Thread]) -> None:
    """Close the child's output pipes once their readers are done (the child has exited or
    closed them)."""
    for reader in readers:
        reader.join(timeout=5)
    if not any(reader.is_alive() for reader in readers):
        for pipe in (proc.stdout, proc.stderr):
            if pipe is not None:
                pipe.close()


@dataclass
class EngineError(Exception):
    """The engine failed: its own one-line error (``field``/``reason`` for an option), or a crash
    described with its last lines of standard error."""

    message: str
    field: str | None = None
    reason: str | None = None
    crashed: bool = False

    def __str__(self) -> str:
        return self.message


@dataclass
class Events:
    """Where the protocol's lines go."""

    progress: Callable[[float], None] = lambda _p: None
    log: Callable[[str], None] = lambda _m: None
    warning: Callable[[str], None] = lambda _m: None
    debug: Callable[[str], None] = lambda _m: None
    cancelled: Callable[[], bool] = lambda: False
    stderr: deque = field(default_factory=lambda: deque(maxlen=20))


def run_engine(command: Sequence[str], env: dict[str, str], events: Events, cwd: str | None = None) -> dict:
    """Run the engine with ``--progress jsonl``; the ``result`` line's fields. Raises
    :class:`EngineError` or :class:`Cancelled`."""
    try:
        proc = start(command, env, cwd)
    except OSError as exc:
        raise EngineError(f"the engine's Python cannot be started ({command[0]}: {exc})", crashed=True) from exc
    result: dict | None = None
    error: dict | None = None
    try:
        for stream, line in lines(proc, events.cancelled):
            if stream == "err":
                events.stderr.append(line)
                if not line.startswith(ERROR_PREFIX):  # its error line: the error event says it once
                    events.debug(line)
                continue
            event = _event(line)
            if event is None:
                events.debug(line)
            elif event["type"] == "result":
                result = event
            elif event["type"] == "error":
                error = event
            else:
                _dispatch(event, events)
        code = exit_code(proc)
    finally:
        if proc.poll() is None:
            stop(proc)
        for pipe in (proc.stdin, proc.stdout, proc.stderr):
            try:
                pipe.close()
            except (OSError, ValueError, AttributeError):
                pass
    if code == 0 and result is not None:
        return result
    if error is not None:
        raise EngineError(error.get("message") or "failed", error.get("field"), error.get("reason"))
    raise EngineError(crash_text(code, events.stderr), crashed=True)


def _event(line: str) -> dict | None:
    if not line.startswith("{"):
        return None
    try:
        event = json.loads(line)
    except ValueError:
        return None
    return event if isinstance(event, dict) and "type" in event else None


def _dispatch(event: dict, events: Events) -> None:
    kind = event["type"]
    if kind == "progress":
        events.progress(float(event.get("percent") or 0.0))
    elif kind == "log":
        events.log(str(event.get("message") or ""))
    elif kind == "warning":
        events.warning(str(event.get("message") or ""))


def crash_text(code: int, tail: Sequence[str]) -> str:
    """One message for a child that ended without its own error line."""
    how = f"exit status {code}"
    if platforms.is_windows() and (code > 255 or code < -255):  # an NTSTATUS: 0xC0000005, not 3221225477
        status = code & 0xFFFFFFFF
        how = f"exit status 0x{status:08X}" + (f", {WINDOWS_CRASHES[status]}" if status in WINDOWS_CRASHES else "")
    elif code < 0:
        try:
            how = f"signal {signal.Signals(-code).name}"
        except ValueError:
            how = f"signal {-code}"
    last = "\n".join(list(tail)[-12:]) or "(nothing on its standard error)"
    return f"The soil volume engine stopped unexpectedly ({how}). Its last lines:\n{last}"
