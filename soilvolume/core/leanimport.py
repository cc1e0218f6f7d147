"""pyproj imported without the modules it loads for functions the engine never calls.

pyproj's ``__init__`` imports ``pyproj.sync`` (grid downloads: urllib.request, http.client, ssl,
email) and ``pyproj._show_versions`` (importlib.metadata), ~25 ms of every run's start-up, for
``TransformerGroup.download_grids`` and ``pyproj.show_versions``. While pyproj loads, both are
stand-ins; a name taken from one is a function that imports the real module when it is called
and calls the real function, so pyproj behaves as before; the stand-ins leave ``sys.modules``
once pyproj is loaded (a later ``import pyproj.sync`` imports the real module).
"""

from __future__ import annotations

import importlib
import sys
import types

STAND_INS = ("pyproj.sync", "pyproj._show_versions")


class _StandIn(types.ModuleType):
    """A module whose every public name is a function deferring to the real module's."""

    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        name = self.__name__

        def deferred(*args, **kwargs):
            return getattr(importlib.import_module(name), attr)(*args, **kwargs)

        deferred.__name__ = deferred.__qualname__ = attr
        return deferred


def import_pyproj() -> None:
    """Import pyproj with :data:`STAND_INS` in place (once; nothing when it is imported already).
    Should a pyproj release use something of them while it loads, it is imported again the
    ordinary way; a pyproj that cannot be imported is left to the import that needs it."""
    if "pyproj" in sys.modules:
        return
    placed = {name: _StandIn(name) for name in STAND_INS if name not in sys.modules}
    sys.modules.update(placed)
    try:
        import pyproj  # noqa: F401
    except Exception:  # noqa: BLE001 - the module that failed is out of sys.modules: imported again below
        pass
    finally:
        for name, module in placed.items():
            if sys.modules.get(name) is module:
                del sys.modules[name]
    try:
        import pyproj  # noqa: F401, F811
    except ImportError:  # not installed (or numpy missing): the command's own import says which
        pass
