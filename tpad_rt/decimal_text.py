"""Numbers written as text: plain ASCII decimals only.

Python's ``float`` also takes ``1_000``, digits of other scripts (``٣١``, ``３１``),
``infinity`` and ``nan``; a measurement file, a URL option or a flag that holds one is a
mistake to report, not a number to guess. Every value tpad-rt reads from text (CSV
cells, URL options, command-line numbers) goes through :func:`parse_decimal`.

API map
-------
parse_decimal(text, allow_inf=False) -> float
    the number ``text`` writes (surrounding spaces allowed); ValueError for anything else
parse_whole(text) -> int
    the whole number ``text`` writes in ASCII digits (sign and surrounding spaces allowed); ValueError otherwise
"""

from __future__ import annotations

import math
import re

#: Optional sign, digits with at most one point (or a point and digits), optional exponent; ASCII only.
_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)
#: Optional sign and ASCII digits, at most MAX_WHOLE_DIGITS of them (int() of a huge string is slow).
MAX_WHOLE_DIGITS = 30
_WHOLE = re.compile(rf"[+-]?[0-9]{{1,{MAX_WHOLE_DIGITS}}}", re.ASCII)


def parse_decimal(text: str, allow_inf: bool = False) -> float:
    """The number ``text`` writes as a plain decimal (``12``, ``-0.5``, ``3e4``), surrounding spaces allowed; with
    ``allow_inf``, ``inf`` or ``+inf`` too. Raises ValueError for anything else. The value may still overflow to
    infinity (``1e999``): range checks come after.

    Fast for the common case (a trajectory holds millions of numbers): ``float`` reads the
    text; what it takes beyond a plain decimal is told apart around it: ``_`` and non-ASCII
    digits before, the words ``inf`` and ``nan`` after (their value is not finite). White
    space around the number is allowed, as ``float`` allows it."""
    if text.isascii() and "_" not in text:
        try:
            value = float(text)
        except ValueError:
            pass
        else:
            if math.isfinite(value) or _DECIMAL.fullmatch(text.strip()) is not None:
                return value  # finite, or a plain decimal that overflows
    if allow_inf and text.strip() in ("inf", "+inf"):
        return math.inf
    raise ValueError(f"not a plain decimal number: {text!r}")


def parse_whole(text: str) -> int:
    """The whole number ``text`` writes in ASCII digits (``12``, ``-3``), surrounding spaces allowed. Raises
    ValueError for anything else (``1_000``, ``1e3``, ``12.0``, digits of other scripts, more than
    MAX_WHOLE_DIGITS digits)."""
    stripped = text.strip(" \t")
    if _WHOLE.fullmatch(stripped) is None:
        raise ValueError(f"not a whole number: {text!r}")
    return int(stripped)
