"""The server's pages (`templates/`) with their styles and scripts (`static/`), and the one Jinja environment that
renders every page the server writes: participant and admin pages and the report."""

from __future__ import annotations

from datetime import UTC, datetime
from functools import cache
from html import escape
from pathlib import Path

from jinja2 import Environment, FileSystemLoader
from markupsafe import Markup

APP_DIR = Path(__file__).resolve().parent


def _shipped(name: str) -> Path:
    """A source checkout keeps the folder beside `app/`; an installed wheel carries it inside `app/` (the build
    configuration maps it there)."""
    for folder in (APP_DIR / name, APP_DIR.parent / name):
        if folder.is_dir():
            return folder
    raise FileNotFoundError(f"the server's {name}/ folder is missing beside or inside {APP_DIR}: reinstall foil")


TEMPLATES_DIR = _shipped("templates")
STATIC_DIR = _shipped("static")


def _paragraphs(text: str) -> list[str]:
    return [" ".join(block.split()) for block in text.strip().split("\n\n") if block.strip()]


def _strong(text: str) -> Markup:
    """A world's legend line (`app.visible.Words`), escaped for a page's text (quotes need none there), with its
    ``**words**`` in bold: the manifest carries plain text, never markup."""
    parts = escape(text, quote=False).split("**")
    return Markup("".join(f"<strong>{part}</strong>" if k % 2 else part for k, part in enumerate(parts)))


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.2f}%"


def _p_value(value: float | None) -> str:
    return "–" if value is None else ("< 0.001" if value < 1e-3 else f"{value:.3g}")


def _number(value: float | None) -> str:
    return "–" if value is None else f"{value:.3g}"


def _sentence(text: str) -> str:
    """A note as a sentence: its first letter upper case and the rest as written (Jinja's `capitalize` would lower
    the case of every other letter, names and units included)."""
    return text[:1].upper() + text[1:]


def _moment(value: datetime | None) -> str:
    """A stored time in ISO 8601 with its time zone, to the minute."""
    if value is None:
        return "–"
    return (value if value.tzinfo else value.replace(tzinfo=UTC)).isoformat(timespec="minutes")  # stored in UTC


@cache
def page_templates() -> Environment:
    """Compiled once per process: no check for changed files on every page."""
    env = Environment(loader=FileSystemLoader(TEMPLATES_DIR), autoescape=True, auto_reload=False)
    env.filters.update(
        paragraphs=_paragraphs,
        strong=_strong,
        percent=_percent,
        p=_p_value,
        num=_number,
        moment=_moment,
        sentence=_sentence,
    )
    return env
