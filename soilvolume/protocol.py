"""``--progress jsonl``: the command line's machine-readable progress, one JSON object per line.

Front ends running the engine as a subprocess (QGIS) read these, never human text. Each has a ``type``:

- ``progress``: ``percent`` (0-100) and ``message``;
- ``log``: ``message`` (a step or a note, once each);
- ``warning``: ``message`` (a Python warning raised during the run);
- ``error``: ``message`` (one line), ``exit`` (the exit status), and for an option out of its
  range ``field`` (the option's name in :class:`soilvolume.options.Options`) and ``reason``;
- ``result``: ``command`` and what the command returns (estimate: ``report``, ``outputs``,
  ``summary``), the last line of a successful run.

Texts name options by key, as markers of :mod:`soilvolume.core.wording` (``{opt:scheduler=none}``), never as
flags: the front end words them (the QGIS plugin as its parameter). The ``result`` line's ``report`` is
report.json (worded for the command line), its ``summary`` keeps the markers.

The lines go to the original standard output (anything else there, such as C libraries' prints, to standard
error). A line ``cancel`` on standard input cancels the run as a user's Cancel does (nothing written; exit 1
with an ``error`` line). Stdlib only.
"""

from __future__ import annotations

import json
import math
import os
import sys
import threading
import warnings
from typing import IO, Any


def _plain(value: Any) -> Any:
    """JSON for numpy values and paths (``tolist`` covers numpy arrays and scalars)."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def _finite(value: Any) -> Any:
    """NaN and infinities as null: the lines stay strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value  # a Path: str by _plain


class Protocol:
    """Writes the protocol's lines (thread-safe); ``cancelled`` is set by a ``cancel`` line on standard input."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.cancelled = threading.Event()
        self._lock = threading.Lock()

    def emit(self, kind: str, **fields: Any) -> None:
        line = json.dumps(_finite({"type": kind, **fields}), default=_plain, allow_nan=False)
        with self._lock:
            self.stream.write(line + "\n")
            self.stream.flush()

    def progress(self, percent: float, message: str) -> None:
        self.emit("progress", percent=round(float(percent), 2), message=message)

    def log(self, message: str) -> None:
        self.emit("log", message=message)


def open_protocol() -> Protocol:
    """The protocol on the original standard output, fd 1 and ``sys.stdout`` then on standard error; Python
    warnings become ``warning`` lines (once per message); a ``cancel`` line on standard input cancels (its end
    is ignored)."""
    sys.stdout.flush()
    stream = os.fdopen(os.dup(1), "w", buffering=1, encoding="utf-8", errors="backslashreplace")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    proto, seen, source = Protocol(stream), set(), sys.stdin

    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ARG001
        text = f"{category.__name__}: {message}"
        if text not in seen:
            seen.add(text)
            proto.emit("warning", message=text)

    def watch() -> None:
        try:
            for line in source:
                if line.strip() == "cancel":
                    proto.cancelled.set()
                    return
        except (OSError, ValueError):
            return

    warnings.showwarning = show
    if source is not None and not source.isatty():
        threading.Thread(target=watch, name="soilvolume-cancel", daemon=True).start()
    return proto
