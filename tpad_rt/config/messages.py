"""Pydantic validation errors in plain English, located without union tags."""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from typing import Any

from pydantic_core import ErrorDetails

from tpad_rt.config.breadcrumb import Location, breadcrumb, show_value
from tpad_rt.config.fields import RULE_ERROR
from tpad_rt.config.locate import Spot, locate

_Explain = Callable[[ErrorDetails, Spot, list[Spot]], str]

#: Most problems one ConfigError lists; the rest are counted in a last line (a file of 50,000 unknown keys
#: gets a message of a few KB, not of MBs).
MAX_LISTED_ERRORS = 100


def listed(lines: list[str], source: str, total: int | None = None) -> list[str]:
    """The first MAX_LISTED_ERRORS of ``lines`` (breadcrumbs of ``source``'s problems; ``total`` of them, default
    as many as given), and ``and N more problems`` when there are more."""
    total = len(lines) if total is None else total
    if total <= MAX_LISTED_ERRORS:
        return lines
    return [*lines[:MAX_LISTED_ERRORS], breadcrumb(source, (), f"and {total - MAX_LISTED_ERRORS:,} more problems "
                                                   f"(the first {MAX_LISTED_ERRORS} are listed)")]


def explain(error: ErrorDetails, root: Any) -> tuple[Location, str]:
    """The clean location of ``error`` (validated against type ``root``) and its message."""
    loc, spots = locate(root, error["loc"])
    kind = error["type"]
    ctx = error.get("ctx", {})
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        return (*loc, spots[-1].discriminator or "?"), _explain_tag(error, spots[-1])
    if kind == RULE_ERROR:
        return (*loc, *ctx.get("key", ())), error["msg"]
    is_key = bool(loc) and loc[-1] == "[key]"  # pydantic's marker for a bad mapping key
    message = _EXPLAIN.get(kind, _explain_other)(error, spots[-1], spots)
    return (loc[:-1], f"key {message}") if is_key else (loc, message)


def did_you_mean(word: Any, choices: list[Any]) -> str:
    """``"; did you mean 'x'?"`` for the closest choice, or ``""`` if none is close."""
    if not isinstance(word, str):
        return ""
    matches = difflib.get_close_matches(word, [str(choice) for choice in choices], n=1)
    return f"; did you mean '{matches[0]}'?" if matches else ""


def _got(error: ErrorDetails) -> str:
    return f", got {show_value(error['input'])}"


def _explain_tag(error: ErrorDetails, spot: Spot) -> str:
    choices = ", ".join(spot.choices())
    if error["type"] == "union_tag_not_found":
        return f"required key missing (one of {choices})"
    given = error["input"]
    tag = given.get(spot.discriminator, error["ctx"]["tag"]) if isinstance(given, dict) else error["ctx"]["tag"]
    return f"must be one of {choices}; got {show_value(tag)}{did_you_mean(tag, spot.choices())}"


def _explain_literal(error: ErrorDetails, spot: Spot, spots: list[Spot]) -> str:
    choices = spot.choices()
    shown = ", ".join(str(choice) for choice in choices) or error["ctx"]["expected"]
    return f"must be one of {shown}; got {show_value(error['input'])}{did_you_mean(error['input'], choices)}"


def _explain_extra(error: ErrorDetails, spot: Spot, spots: list[Spot]) -> str:
    return f"unknown key{did_you_mean(error['loc'][-1], spots[-2].keys())}"


def _explain_other(error: ErrorDetails, spot: Spot, spots: list[Spot]) -> str:
    message = error["msg"]
    return f"{message[:1].lower()}{message[1:]}{_got(error)}"


def _explain_bound(symbol: str, bound: str) -> _Explain:
    return lambda error, spot, spots: f"must be {symbol} {error['ctx'][bound]:g}{_got(error)}"


def _explain_length(error: ErrorDetails, spot: Spot, spots: list[Spot]) -> str:
    ctx = error["ctx"]
    count = spot.fixed_length()
    if count is not None:
        return f"must be a list of exactly {count} items{_got(error)}"
    if error["type"] == "too_short":
        least = ctx["min_length"]
        return f"must have at least {least} item{'s' * (least != 1)}, got {ctx['actual_length']}"
    return f"must have at most {ctx['max_length']} items, got {ctx['actual_length']}"


def _explain_type(error: ErrorDetails, spot: Spot, spots: list[Spot]) -> str:
    expected = _TYPE_NAMES[error["type"]]
    hint = _NUMBER_AS_TEXT if expected in ("a number", "a whole number") and _reads_as_number(error["input"]) else ""
    return f"must be {expected}{_got(error)}{hint}"


_NUMBER_AS_TEXT = " (text: write numbers without quotes, and exponents with a dot as in 1.0e-3)"


def _reads_as_number(given: Any) -> bool:
    """True for text such as ``'2.5'`` or ``'1e-3'`` (YAML 1.1 reads an exponent without a dot as text)."""
    if not isinstance(given, str):
        return False
    try:
        return math.isfinite(float(given))
    except ValueError:
        return False


def _expect(text: str) -> _Explain:
    return lambda error, spot, spots: text


_TYPE_NAMES = {
    "float_type": "a number",
    "float_parsing": "a number",
    "int_type": "a whole number",
    "int_parsing": "a whole number",
    "int_from_float": "a whole number",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "string_type": "text",
    "list_type": "a list",
    "tuple_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
    "path_type": "a file path",
}

_EXPLAIN: dict[str, _Explain] = {
    "missing": _expect("required key missing"),
    "extra_forbidden": _explain_extra,
    "literal_error": _explain_literal,
    "greater_than": _explain_bound(">", "gt"),
    "greater_than_equal": _explain_bound(">=", "ge"),
    "less_than": _explain_bound("<", "lt"),
    "less_than_equal": _explain_bound("<=", "le"),
    "finite_number": lambda error, spot, spots: f"must be a finite number{_got(error)}",
    "string_too_short": _expect("must not be empty"),
    "too_short": _explain_length,
    "too_long": _explain_length,
    **{kind: _explain_type for kind in _TYPE_NAMES},
}
