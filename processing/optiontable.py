"""The engine's option table as QGIS's Python sees it, and engine messages in its words.

QGIS's own Python imports nothing of the engine but its standard-library-only modules
(``soilvolume.options``, ``soilvolume.core.wording``), loaded from the copy inside the plugin
folder: the fields each command takes, their parameter names and labels, and engine messages
that name options by key worded with those parameters instead of command-line flags. Below
:mod:`.engine` (running the engine) and :mod:`.optionparams` (the Processing parameters), which
both use it.
"""

from __future__ import annotations

import html
import importlib
import importlib.util
import sys
from dataclasses import Field, fields
from pathlib import Path
from types import ModuleType

PLUGIN_DIR = Path(__file__).resolve().parent.parent
SKIPPED = {"keep_registered_cloud"}  # an output destination, not a parameter
UNIT_TEXT = {"m": "m", "m2": "m²", "deg": "°"}


def ensure_engine_package() -> None:
    """Make the engine's package importable as top-level ``soilvolume`` (for its option table):
    an already imported one, else the copy shipped inside the plugin folder, loaded by file
    location (never by putting the plugin folder on ``sys.path``)."""
    if "soilvolume" in sys.modules:
        return
    bundled = PLUGIN_DIR / "soilvolume" / "__init__.py"
    spec = importlib.util.spec_from_file_location(
        "soilvolume", bundled, submodule_search_locations=[str(bundled.parent)]
    )
    if spec is None or spec.loader is None:  # pragma: no cover - defensive
        raise ImportError(f"cannot load the engine from {bundled}")
    module = importlib.util.module_from_spec(spec)
    sys.modules["soilvolume"] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules["soilvolume"]
        raise


def engine(name: str = "options") -> ModuleType:
    """A standard-library-only engine module (``options``, ``wording``): nothing else is imported here."""
    ensure_engine_package()
    return importlib.import_module(f"soilvolume.{name}")


def options_class() -> type:
    """The engine's Options class (pure Python: importable without the engine's dependencies)."""
    return engine("options").Options


def option_fields(command: str = "estimate") -> list[Field]:
    """The option table's fields that the engine's ``command`` takes (the table declares it next
    to each option), in table order."""
    table = fields(options_class())
    return [f for f in table if f.name not in SKIPPED and command in f.metadata.get("commands", ("estimate",))]


def key(field: Field) -> str:
    return field.name.upper()


def description(field: Field) -> str:
    """The field's label with its unit for plain numbers (distance widgets show their own)."""
    meta = field.metadata
    label = meta.get("label") or field.name.replace("_", " ").capitalize()
    unit = meta.get("unit")
    if unit and unit != "m":
        label = f"{label} ({UNIT_TEXT.get(unit, unit)})"
    if field.default is None and is_number(field):
        label = f"{label} (automatic when not set)"
    return label


def is_number(field: Field) -> bool:
    return value_kind(field) in ("float", "int")


def value_kind(field: Field) -> str:
    """float, int, bool or str, from the field's annotation (``float | None`` -> float)."""
    text = str(field.type)
    for kind in ("bool", "float", "int"):
        if text.startswith(kind):
            return kind
    return "str"


def parameter_names() -> dict[str, str]:
    """Option key -> "'Label' (NAME)" for every option of the engine's table."""
    names = {f.name: f"'{description(f)}' ({key(f)})" for f in option_fields()}
    names["crs"] = "'CRS override' (CRS)"
    return names


def parameter_name(option: str, value: str | None = None, names: dict[str, str] | None = None) -> str:
    """An option the engine names by key (``soilvolume.wording``) as its Processing parameter:
    "'Coarse registration' (COARSE)", with its value "... (COARSE) = fpfh"."""
    name = (names or parameter_names()).get(option) or engine("core.wording").flag(option)
    return name if value is None else f"{name} = {value}"


def qgis_wording(message: str) -> str:
    """An engine message (options by key) as a sentence naming Processing parameters:
    "{opt:coarse=fpfh} forces it" -> "'Coarse registration' (COARSE) = fpfh forces it"."""
    names = parameter_names()
    text = engine("core.wording").render(message, lambda k, v: parameter_name(k, v, names))
    return text[:1].upper() + text[1:]


def reword_html(page: str) -> str:
    """An engine HTML report with its options (``<span data-option>`` elements) named by their
    parameters; the rest of the page untouched."""
    names = parameter_names()
    return engine("core.wording").html_render(page, lambda k, v: html.escape(parameter_name(k, v, names), quote=False))


def option_error_text(exc: Exception) -> str | None:
    """An engine option error (it names the option's field) worded with the parameter."""
    field, reason = getattr(exc, "field", None), getattr(exc, "reason", None)
    if not field or not reason:
        return None
    match = [f for f in option_fields() if f.name == field]
    if not match:
        return None
    return f"Incorrect parameter value for '{description(match[0])}' ({key(match[0])}): {reason}"
