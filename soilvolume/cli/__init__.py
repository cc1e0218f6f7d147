"""Command line: ``soilvolume estimate BEFORE AFTER --out DIR`` and friends.

One module per command, each declaring its sub-parser (``add_parser``) beside what it runs
(``run``); :mod:`.app` names them in its registry, builds the parser (loading the module of the
command being run only) and owns the one error path. Options and their help come from
:class:`soilvolume.options.Options` (:mod:`.flags`): ``--help`` explains every knob.
"""

from .app import build_parser, main, one_line
from .flags import add_options, add_progress, options_from

__all__ = ["add_options", "add_progress", "build_parser", "main", "one_line", "options_from"]
