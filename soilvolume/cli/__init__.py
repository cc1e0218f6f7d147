"""Command line: ``soilvolume estimate BEFORE AFTER --out DIR`` and friends, one module per command
(its ``add_parser`` and ``run``), named in :mod:`.app`'s registry; options and their help come from
:class:`soilvolume.options.Options` (:mod:`.flags`)."""

from .app import build_parser, main

__all__ = ["build_parser", "main"]
