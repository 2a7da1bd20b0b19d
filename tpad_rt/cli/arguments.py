"""argparse types the subcommands share: bounded numbers, refused in one line naming the range.

API map
-------
number(low, low_closed, high=inf, what="") -> type
    a finite number above ``low`` (or equal, when ``low_closed``), at most ``high``
whole(high, what, low=1) -> type
    a whole number in ``[low, high]``
Subparsers
    the type of ``ArgumentParser.add_subparsers()``, which each subcommand's ``add_parser`` takes

``what`` (the unit, or why the bound) is shown in the message: ``argument --rate: must be
a whole number in [1, 768000] (Hz, the highest rate tpad-rt runs at), got '1e9'``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TypeAlias

from tpad_rt.decimal_text import parse_decimal, parse_whole

#: argparse names the type ``add_subparsers()`` returns only privately, and documents no public
#: base for it: this alias is the one place the private name appears.
Subparsers: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"

def decimal(text: str) -> float:
    """An argparse type: a plain decimal number (:func:`tpad_rt.decimal_text.parse_decimal`; NaN, infinities and
    ``1_000`` refused); ranges are the command's to check."""
    try:
        value = parse_decimal(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got '{text}'")
    return value


def whole(high: int, what: str, low: int = 1) -> Callable[[str], int]:
    """An argparse type: a whole number in [``low``, ``high``] (``what`` says what the bound is)."""
    def parse(text: str) -> int:
        try:
            value = parse_whole(text)
        except ValueError:
            value = low - 1
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be a whole number in [{low}, {high}] ({what}), got '{text}'")
        return value

    return parse


def number(low: float, low_closed: bool, high: float = math.inf, what: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number above ``low`` (or equal, when ``low_closed``), at most ``high``."""
    expected = f"{'>=' if low_closed else '>'} {low:g}"
    if high < math.inf:
        expected = f"in {'[' if low_closed else '('}{low:g}, {high:g}]" + (f" ({what})" if what else "")

    def parse(text: str) -> float:
        try:
            value = parse_decimal(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and (value >= low if low_closed else value > low) and value <= high):
            raise argparse.ArgumentTypeError(f"must be a number {expected}, got '{text}'")
        return value

    return parse
