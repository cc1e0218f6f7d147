"""What a running command tells its caller: progress and log (hooks), and its result."""

from __future__ import annotations

import argparse
import json
import sys

from ..core.hooks import Hooks


def hooks(ns: argparse.Namespace) -> Hooks:
    """The protocol's progress, log and cancel; else progress for people on stderr where the command has
    ``--quiet`` (the estimate) and it is not given; else none (dem, register, volume print only JSON)."""
    if ns.protocol is not None:
        return Hooks(
            progress=ns.protocol.progress, log=ns.protocol.log, cancel=ns.protocol.cancelled.is_set, keyed=True
        )
    if getattr(ns, "quiet", True):
        return Hooks()

    def show(pct: float, msg: str) -> None:
        print(f"[{pct:5.1f}%] {msg}", file=sys.stderr, flush=True)

    return Hooks(progress=show)


def result(ns: argparse.Namespace, data: dict, lines: list[str] | None = None) -> int:
    """Send ``data`` as the protocol's last line, else print ``lines`` (default: ``data`` as JSON); exit 0."""
    if ns.protocol is not None:
        ns.protocol.emit("result", command=ns.command, **data)
    else:
        print("\n".join(lines) if lines is not None else json.dumps(data, indent=2))
    return 0
