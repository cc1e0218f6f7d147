"""What a running command tells its caller: progress and log (hooks), and its result."""

from __future__ import annotations

import argparse
import sys

from ..core.hooks import Hooks
from ..protocol import Protocol


def hooks(ns: argparse.Namespace) -> Hooks:
    """The protocol's progress, log and cancel; else progress for people on stderr where the command has
    ``--quiet`` (the estimate) and it is not given; else none (dem, register, volume print only JSON)."""
    proto: Protocol | None = getattr(ns, "protocol", None)
    if proto is not None:
        return Hooks(progress=proto.progress, log=proto.log, cancel=proto.is_cancelled, keyed=True)
    if getattr(ns, "quiet", True):
        return Hooks()

    def show(pct: float, msg: str) -> None:
        print(f"[{pct:5.1f}%] {msg}", file=sys.stderr, flush=True)

    return Hooks(progress=show)


def send_result(ns: argparse.Namespace, **data) -> bool:
    """Send a command's result as the protocol's last line; False without the protocol."""
    proto: Protocol | None = getattr(ns, "protocol", None)
    if proto is None:
        return False
    proto.emit("result", command=ns.command, **data)
    return True
