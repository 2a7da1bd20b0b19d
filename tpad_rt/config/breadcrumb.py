"""Breadcrumb lines: ``<file>: <path.to[1].key>: <what is wrong> (line N)``."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from tpad_rt.errors import printable

Location = tuple[str | int, ...]

_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MAX_SHOWN_CHARS = 60


def format_path(loc: Sequence[Any]) -> str:
    """``('layers', 1, 'period_mm')`` -> ``layers[1].period_mm`` (odd keys quoted)."""
    parts: list[str] = []
    for elem in loc:
        if isinstance(elem, int) and not isinstance(elem, bool):
            parts.append(f"[{elem}]")
        elif isinstance(elem, str) and _KEY.fullmatch(elem):
            parts.append(f".{elem}" if parts else elem)
        else:
            parts.append(f"[{show_value(elem)}]")
    return "".join(parts)


def breadcrumb(source: str | None, loc: Sequence[Any], message: str, line: int | None = None) -> str:
    """One error line; ``source`` (the file) and an empty ``loc`` are left out.

    Control characters (a newline in a file name) are escaped, so the line stays one line.
    """
    parts = [part for part in (source, format_path(loc)) if part]
    text = printable(": ".join([*parts, message]))
    return f"{text} (line {line})" if line is not None else text


def show_value(value: Any) -> str:
    """A short YAML-flavoured rendering of a value the user wrote (at most 60 characters)."""
    text = _render(value, _MAX_SHOWN_CHARS + 1)
    return text if len(text) <= _MAX_SHOWN_CHARS else text[: _MAX_SHOWN_CHARS - 3] + "..."


def _render(value: Any, budget: int) -> str:
    """Render ``value``, stopping early once ``budget`` characters are exceeded."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return _render_items((f"{_render(k, budget)}: {_render(v, budget)}" for k, v in value.items()), "{}", budget)
    if isinstance(value, (list, tuple)):
        return _render_items((_render(item, budget) for item in value), "[]", budget)
    return repr(value)


def _render_items(items: Any, brackets: str, budget: int) -> str:
    text = brackets[0]
    for item in items:
        text += (", " if len(text) > 1 else "") + item
        if len(text) > budget:
            return text
    return text + brackets[1]
