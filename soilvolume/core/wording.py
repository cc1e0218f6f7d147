"""Options marked by key in the engine's messages (``{opt:KEY}``, ``{opt:KEY=VALUE}``: :func:`opt`), worded by
each front end (:func:`render`): ``--key value`` (:func:`cli`, :func:`cli_tree`), QGIS's parameter, report.html's
``<span data-option=KEY>`` (:func:`html`); ``--progress jsonl`` keeps them. Standard library only (QGIS imports it)."""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

MARKER = re.compile(r"\{opt:([a-z][a-z0-9_]*)(?:=([^{}]*))?\}")
SPAN = re.compile(r'<span class="option" data-option="([a-z][a-z0-9_]*)"(?: data-value="([^"]*)")?>[^<]*</span>')


def opt(key: str, value: object = None) -> str:
    """The marker of option ``key`` (``value``: what it is set to, shown beside its name)."""
    return f"{{opt:{key}}}" if value is None else f"{{opt:{key}={value}}}"


def flag(key: str) -> str:
    """The command-line flag of option ``key`` (``before_crs`` -> ``--before-crs``)."""
    return "--" + key.replace("_", "-")


def render(text: str, name: Callable[[str, str | None], str]) -> str:
    """``text`` with every marker replaced by ``name(key, value)`` (value None when not given)."""
    return MARKER.sub(lambda m: name(m.group(1), m.group(2)), text)


def cli_name(key: str, value: str | None) -> str:
    """A marker in the command line's words: ``--key`` or ``--key value``."""
    return flag(key) if value is None else f"{flag(key)} {value}"


def cli(text: str) -> str:
    """``text`` in the command line's words."""
    return render(text, cli_name)


def cli_tree(value: Any) -> Any:
    """A JSON-like value (a report) with every string in the command line's words."""
    if isinstance(value, str):
        return cli(value) if "{opt:" in value else value
    if isinstance(value, dict):
        return {k: cli_tree(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(cli_tree(v) for v in value)
    return value


def _span(key: str, value: str | None) -> str:
    data = "" if value is None else f' data-value="{value}"'
    return f'<span class="option" data-option="{key}"{data}>{cli_name(key, value)}</span>'


def html(page: str) -> str:
    """An HTML page (its text already escaped) with every marker as a ``span`` naming the
    option, its text the command line's words; :func:`html_render` words them otherwise."""
    return render(page, _span)


def html_render(page: str, name: Callable[[str, str | None], str]) -> str:
    """A page of :func:`html` with each option's span replaced by ``name(key, value)`` (the
    caller escapes what it returns)."""
    return SPAN.sub(lambda m: name(m.group(1), m.group(2)), page)
