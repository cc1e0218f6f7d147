"""Libraries imported without the modules they load for functions the engine never calls.

pyproj's ``__init__`` imports ``pyproj.sync`` (grid downloads: urllib.request, http.client, ssl,
email) and ``pyproj._show_versions`` (importlib.metadata), ~25 ms of every run's start-up, for
``TransformerGroup.download_grids`` and ``pyproj.show_versions``. :func:`install` makes the next
import of pyproj, whoever asks for it and whenever (a command that never needs pyproj never loads
it), run with both replaced by stand-ins; a name taken from one is a function that imports the
real module when it is called and calls the real function, so pyproj behaves as before. The
stand-ins leave ``sys.modules`` once pyproj is loaded (a later ``import pyproj.sync`` imports the
real module).

:func:`without` hides optional extras, imported at a library's import when installed, from the
imports made inside it: ``requests`` (laspy's COPC reader over HTTP, ~30 ms) and ``jinja2``
(Dask's notebook HTML, ~15-25 ms). The library sees them as not installed, as it allows.
:func:`fast_yaml` parses YAML with LibYAML inside (Dask and Distributed read their defaults as
they are imported: 12 ms in Python's loader, 2 ms in LibYAML's, the same documents).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
from collections.abc import Iterator
from contextlib import contextmanager

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


class _Loader(importlib.abc.Loader):
    """pyproj's own loader, running its ``__init__`` with :data:`STAND_INS` in place; should a
    pyproj release use something of them while it loads, it runs again without them."""

    def __init__(self, real: importlib.abc.Loader) -> None:
        self.real = real

    def __getattr__(self, attr: str):  # resources, file names: the real loader's
        return getattr(self.real, attr)

    def create_module(self, spec):
        return self.real.create_module(spec)

    def exec_module(self, module) -> None:
        placed = {name: _StandIn(name) for name in STAND_INS if name not in sys.modules}
        sys.modules.update(placed)
        try:
            self.real.exec_module(module)
            return
        except Exception:  # noqa: BLE001 - the submodule that failed is out of sys.modules: run again below
            pass
        finally:
            for name, stand_in in placed.items():
                if sys.modules.get(name) is stand_in:
                    del sys.modules[name]
        self.real.exec_module(module)  # the ordinary way (a pyproj that cannot load says why here)


class _Finder(importlib.abc.MetaPathFinder):
    """Finds pyproj, once, through the other finders, and hands it :class:`_Loader`."""

    def find_spec(self, name, path=None, target=None):
        if name != "pyproj":
            return None
        uninstall()
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            spec.loader = _Loader(spec.loader)
        return spec


def install() -> None:
    """Have the next import of pyproj load it lean (nothing when it is imported already)."""
    if "pyproj" not in sys.modules and not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())


def uninstall() -> None:
    """Imports of pyproj the ordinary way again."""
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _Finder)]


#: optional extras libraries import when installed, for functions the engine never calls:
#: requests (laspy: COPC over HTTP), jinja2 (Dask: notebook HTML of its objects)
EXTRAS = ("requests", "jinja2")


def hide(names: tuple[str, ...] = EXTRAS) -> list[str]:
    """Imports see the modules ``names`` not imported yet as not installed (``import`` raises
    ModuleNotFoundError), until :func:`unhide`; returns those hidden."""
    hidden = [name for name in names if name not in sys.modules]
    for name in hidden:
        sys.modules[name] = None  # type: ignore[assignment]
    return hidden


def unhide(hidden: list[str]) -> None:
    """The modules :func:`hide` hid importable again (those imported meanwhile stay)."""
    for name in hidden:
        if name in sys.modules and sys.modules[name] is None:
            del sys.modules[name]


@contextmanager
def without(names: tuple[str, ...] = EXTRAS) -> Iterator[None]:
    """The imports inside see ``names`` (those not imported yet) as not installed."""
    hidden = hide(names)
    try:
        yield
    finally:
        unhide(hidden)


def yaml_on_libyaml() -> object | None:
    """``yaml.safe_load`` made LibYAML's (when PyYAML was built with it); returns what
    :func:`yaml_restored` puts back (None: nothing changed)."""
    try:
        import yaml
    except ImportError:
        return None
    loader = getattr(yaml, "CSafeLoader", None)
    if loader is None:
        return None
    plain = yaml.safe_load
    yaml.safe_load = lambda stream: yaml.load(stream, Loader=loader)  # noqa: S506 - the safe loader, in C
    return plain


def yaml_restored(plain: object | None) -> None:
    """``yaml.safe_load`` as it was before :func:`yaml_on_libyaml`."""
    if plain is not None:
        import yaml

        yaml.safe_load = plain


@contextmanager
def fast_yaml() -> Iterator[None]:
    """YAML parsed by LibYAML's safe loader inside (Python's elsewhere, as before)."""
    plain = yaml_on_libyaml()
    try:
        yield
    finally:
        yaml_restored(plain)


@contextmanager
def lean_dask() -> Iterator[None]:
    """Dask and Distributed imported inside without jinja2 (:func:`without`) and with LibYAML
    (:func:`fast_yaml`)."""
    with without(("jinja2",)), fast_yaml():
        yield
