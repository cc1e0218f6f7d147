"""The option table (:class:`soilvolume.options.Options`) as command-line flags, and back."""

from __future__ import annotations

import argparse
from dataclasses import fields

from ..core import wording
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
