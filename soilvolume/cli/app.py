"""The ``soilvolume`` program: the parser made of the command modules, and the one error path (every
failure one line on stderr, and an error line for a program reading the protocol). Only the module
of the command being run is imported (:data:`COMMANDS`); ``--help`` loads them all, to list them."""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import traceback

from ..core.interrupt import handle_signals
from ..core.nativelog import hold_native_stderr, quiet_library_logs, quiet_library_warnings
from ..core.outputs import os_problem
from ..core.types import SoilVolumeError
from ..core.watchdog import out_of_memory, short_of_memory
from ..protocol import Protocol, open_protocol

#: the sub-commands in the order ``--help`` lists them, each a module of this package with its
#: ``add_parser`` and ``run`` (a new command is a new module named here)
COMMANDS = {
    name: f"{__package__}.{name}"
    for name in ("estimate", "dem", "register", "volume", "series", "stockpile", "pipeline", "demo", "selftest")
}


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line and exit 2: ``soilvolume: error: --cell: invalid float
    value: 'abc'`` (its own usage block runs to 30 lines)."""

    def error(self, message: str):
        text = re.sub(r"^argument ([^:/ ]+)(/[^:]+)?: ", r"\1: ", message)
        self.exit(2, f"soilvolume: error: {one_line(text)}\n")


def command(name: str):
    """The module of the command ``name`` (imported now if it was not)."""
    return importlib.import_module(COMMANDS[name])


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The program's parser: one sub-parser per command module; with ``argv`` naming a command
    first, that command's alone is built (the others listed by name, their modules not loaded)."""
    ap = Parser(
        prog="soilvolume",
        description="Soil volume change between two georeferenced point clouds (Shao et al. method, "
        "with robust registration and stable-ground correction).",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    chosen = argv[0] if argv and argv[0] in COMMANDS else None
    for name in COMMANDS:
        if chosen in (None, name):
            command(name).add_parser(sub)
        else:
            sub.add_parser(name)
    return ap


def _fail(message: str, code: int = 1, exc: BaseException | None = None) -> int:
    text = one_line(message)
    if _PROTOCOL:  # the message with its options by key (wording.opt), for the front end to word
        fields = {"field": getattr(exc, "field", None), "reason": getattr(exc, "reason", None)}
        keyed = one_line(exc.keyed) if isinstance(exc, SoilVolumeError) else text
        _PROTOCOL[0].emit("error", message=keyed, exit=code, **{k: v for k, v in fields.items() if v})
    print(f"soilvolume: error: {text}", file=sys.stderr)
    return code


def _out_of_memory() -> int:
    return _fail(out_of_memory(), exc=SoilVolumeError(out_of_memory(keyed=True)))


_PROTOCOL: list[Protocol] = []  # the run's protocol, while one runs


def one_line(message: str, limit: int = 400) -> str:
    """A message on one line of at most ``limit`` characters."""
    text = " ".join(str(message).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def main(argv: list[str] | None = None) -> int:
    """Run one command; every failure is one line on stderr and a non-zero exit: 1 for errors,
    130/143 for SIGINT/SIGTERM (outputs are never half-written)."""
    quiet_library_logs()
    quiet_library_warnings()
    with handle_signals(then_ignore=argv is None):  # None: the program exits right after
        argv = sys.argv[1:] if argv is None else argv
        try:  # the parser imports the command's module: under ulimit -v a library may not map
            ns = build_parser(argv).parse_args(argv)
        except ImportError as exc:
            if not short_of_memory(exc):
                raise
            return _out_of_memory()
        ns.protocol = open_protocol() if getattr(ns, "progress", "text") == "jsonl" else None
        _PROTOCOL[:] = [ns.protocol] if ns.protocol else []
        with hold_native_stderr():  # dropped: no library's message unasked (SOILVOLUME_DEBUG=1 shows them)
            return _run(ns)


def _run(ns: argparse.Namespace) -> int:
    try:
        return command(ns.command).run(ns)
    except SoilVolumeError as exc:  # an Interrupted one exits 130/143
        return _fail(str(exc), getattr(exc, "exit_code", 1), exc)
    except OSError as exc:
        return _fail(str(os_problem(exc)))
    except MemoryError:
        return _out_of_memory()
    except RecursionError:
        return _fail("input nested too deeply")
    except KeyboardInterrupt:  # a signal arrived before the handlers were installed
        return _fail("interrupted", 130)
    except Exception as exc:  # a bug: for a program reading the protocol, an error line too
        if short_of_memory(exc):  # a library that cannot be mapped under ulimit -v
            return _out_of_memory()
        if not _PROTOCOL:
            raise
        traceback.print_exc()
        return _fail(f"internal error ({type(exc).__name__}: {exc}); please report it with the lines above", 1)
