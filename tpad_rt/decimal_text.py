"""Numbers written as text: plain ASCII decimals only.

Python's ``float`` also takes ``1_000``, digits of other scripts (``٣١``, ``３１``),
``infinity`` and ``nan``; a measurement file, a URL option or a flag that holds one is a
mistake to report, not a number to guess. Every value tpad-rt reads from text (CSV
cells, URL options, command-line numbers) goes through :func:`parse_decimal`.

API map
-------
parse_decimal(text, allow_inf=False) -> float
    the number ``text`` writes (surrounding spaces allowed); ValueError for anything else
"""

from __future__ import annotations

import math
import re

#: Optional sign, digits with at most one point (or a point and digits), optional exponent; ASCII only.
_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)


def parse_decimal(text: str, allow_inf: bool = False) -> float:
    """The number ``text`` writes as a plain decimal (``12``, ``-0.5``, ``3e4``), surrounding spaces allowed; with
    ``allow_inf``, ``inf`` or ``+inf`` too. Raises ValueError for anything else. The value may still overflow to
    infinity (``1e999``): range checks come after."""
    stripped = text.strip(" \t")
    if allow_inf and stripped in ("inf", "+inf"):
        return math.inf
    if _DECIMAL.fullmatch(stripped) is None:
        raise ValueError(f"not a plain decimal number: {text!r}")
    return float(stripped)
