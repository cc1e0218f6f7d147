"""The option table (:class:`soilvolume.options.Options`) as command-line flags, and back; what a running
command tells its caller: progress and log (hooks), and its result."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields

from ..core import wording
from ..core.hooks import Hooks
from ..options import Options, command_fields
from ..validate import check_options

SKIP = {"keep_registered_cloud"}  # estimate's --registered-cloud says it


def add_options(p: argparse.ArgumentParser, command: str) -> None:
    """One ``--flag`` per option ``command`` takes (``command_fields``; ``--registered-cloud`` is its own)."""
    for f in (f for f in command_fields(command) if f.name not in SKIP):
        kind = {"float": float, "int": int, "float | None": float}.get(str(f.type), str)
        p.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            type=kind,
            choices=f.metadata["choices"],
            default=None,
            help=f"{wording.cli(f.metadata['help'])} (default: {f.default})",
        )


def add_progress(p: argparse.ArgumentParser) -> None:
    """``--progress text|jsonl``: for people on stderr, or the JSON-lines protocol on stdout."""
    p.add_argument(
        "--progress",
        choices=("text", "jsonl"),
        default="text",
        help="text: progress lines on stderr for people; jsonl: one JSON object per line on stdout "
        "(progress, log, warning, error, result) for programs, and a line 'cancel' on stdin cancels",
    )


def options_from(ns: argparse.Namespace) -> Options:
    """The Options of the parsed flags, each checked against its allowed range."""
    given = {f.name: getattr(ns, f.name) for f in fields(Options) if getattr(ns, f.name, None) is not None}
    if getattr(ns, "registered_cloud", False):
        given["keep_registered_cloud"] = True
    return check_options(Options(**given))


def hooks(ns: argparse.Namespace) -> Hooks:
    """The protocol's progress, log and cancel; else progress for people on stderr where the command has
    ``--quiet`` (the estimate) and it is not given; else none (dem, register, volume print only JSON)."""
    if ns.protocol is not None:
        return Hooks(
            progress=ns.protocol.progress, log=ns.protocol.log, cancel=ns.protocol.cancelled.is_set, keyed=True
        )
    if getattr(ns, "quiet", True):
        return Hooks()
    return Hooks(progress=lambda pct, msg: print(f"[{pct:5.1f}%] {msg}", file=sys.stderr, flush=True))


def result(ns: argparse.Namespace, data: dict, lines: list[str] | None = None) -> int:
    """Send ``data`` as the protocol's last line, else print ``lines`` (default: ``data`` as JSON); exit 0."""
    if ns.protocol is not None:
        ns.protocol.emit("result", command=ns.command, **data)
    else:
        print("\n".join(lines) if lines is not None else json.dumps(data, indent=2))
    return 0
