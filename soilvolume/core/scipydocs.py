"""SciPy's import-time docstring rewriting, skipped in a command-line process.

SciPy (1.15 and later) parses the numpydoc docstrings of ~350 functions while its modules import,
to append notes (array-API capabilities, batching, deprecations) that only its documentation
shows: ~0.1-0.15 s of a run's CPU on text nobody reads in a command's process. :func:`keep_docs`
replaces the parser those decorators call by one that keeps each docstring as it is; nothing but
the ``__doc__`` of SciPy's functions changes. It must run before SciPy is imported, and only
where the process is the engine's own (``python -m soilvolume``, the ``soilvolume`` command), not
in a host such as QGIS, whose console shows SciPy's help.
"""

from __future__ import annotations

import sys

MODULE = "scipy._lib._docscrape"


def keep_docs() -> bool:
    """Install the docstring-keeping parser before SciPy imports; returns whether it was installed
    (False when SciPy is already imported, missing, or its parser is not the expected one)."""
    if "scipy" in sys.modules:
        return False
    try:
        import scipy._lib._docscrape as docscrape  # only scipy/__init__ and this small module
    except ImportError:
        return False
    parser = getattr(docscrape, "FunctionDoc", None)
    sections = getattr(getattr(docscrape, "NumpyDocString", None), "sections", None)
    if not isinstance(parser, type) or not isinstance(sections, dict):
        return False
    docscrape.FunctionDoc = _keeping(parser, sections)
    return True


def _keeping(parser: type, sections: dict) -> type:
    """A subclass of SciPy's ``FunctionDoc`` that does not parse: its sections start empty (what
    the decorators append goes nowhere) and ``str`` gives a signature line and the docstring."""

    class KeptDoc(parser):  # type: ignore[misc, valid-type]
        def __init__(self, func, role: str = "func", doc: str | None = None, config=None) -> None:
            self._f, self._role = func, role
            self._doc = (getattr(func, "__doc__", None) or "") if doc is None else doc
            self._parsed_data = {k: v.copy() if isinstance(v, (list, dict)) else v for k, v in sections.items()}

        def __str__(self) -> str:
            return "\n" + self._doc  # the callers drop the first line (the signature)

    KeptDoc.__qualname__ = KeptDoc.__name__ = "KeptDoc"
    return KeptDoc
