"""Command line: ``soilvolume estimate BEFORE AFTER --out DIR [options]`` and friends.

One module per command, each declaring its sub-parser (``add_parser``) beside what it runs
(``run``); :mod:`.app` lists them, builds the parser and owns the one error path. Options and
their help come from :class:`soilvolume.options.Options` (:mod:`.flags`): ``--help`` explains
every knob.
"""

from .app import build_parser, main, one_line
from .estimate import front_end_summary
from .flags import add_options, add_progress, options_from
from .series import ledger_lines

__all__ = [
    "add_options",
    "add_progress",
    "build_parser",
    "front_end_summary",
    "ledger_lines",
    "main",
    "one_line",
    "options_from",
]
