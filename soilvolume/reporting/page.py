"""The Jinja2 templates of report.html (``templates/``, shipped with the package), rendered with
one :class:`jinja2.Environment`, and the page written whole."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from ..inputs.io import atomic_path

TEMPLATES = Path(__file__).resolve().parent / "templates"


@cache
def environment():
    """The one Jinja2 environment of :data:`TEMPLATES` (Jinja2 loaded when a page is first rendered)."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined

    return Environment(
        loader=FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def render(template: str, **context) -> str:
    """``template`` of :data:`TEMPLATES` rendered with ``context`` (plain text is escaped)."""
    return environment().get_template(template).render(**context)


def write(path: str | Path, text: str) -> Path:
    """Write the page ``text`` to ``path`` atomically (a partial file renamed into place)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
