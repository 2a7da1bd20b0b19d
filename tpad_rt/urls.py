"""Backend URLs, ``scheme://target?option=value&...``, parsed and checked against forms.

Inputs and outputs are chosen by URL (README "Inputs and outputs"). A backend module
describes each URL it accepts with a :class:`UrlForm`: the scheme, the target (a fixed
word such as ``swipe``, or a placeholder such as ``/path/out.wav``) and its options,
each an :class:`Option` with a default and a value parser. A form reads a parsed
:class:`Url` into checked values, and prints itself as the expected form that every
error message ends with.

API map
-------
parse_url(text, direction, schemes) -> Url
    split ``text``; ConfigError for a malformed, over-long or control-character URL or an unknown scheme
Url.fail(problem, forms) -> ConfigError
    the one-line error for a problem with this URL
UrlForm(scheme, target, options).read(url) -> dict of option values
number(...), count(...), flag, point
    value parsers for :class:`Option`
"""

from __future__ import annotations

import difflib
import math
import unicodedata
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl, unquote

from tpad_rt.decimal_text import parse_decimal, parse_whole
from tpad_rt.errors import ConfigError, printable

#: Longest URL accepted (characters).
MAX_URL_CHARS = 4096
#: Characters of a URL shown in a message at most.
_SHOWN_CHARS = 200

#: A value parser: URL text in, checked value out; ValueError says what was expected.
Parser = Callable[[str], Any]


def did_you_mean(word: str, choices: Sequence[str]) -> str:
    """``"; did you mean 'x'?"`` for the choice closest to ``word`` (ignoring case), or ``""`` if none is close."""
    by_lower = {choice.lower(): choice for choice in choices}
    matches = difflib.get_close_matches(word.lower(), list(by_lower), n=1)
    return f"; did you mean '{by_lower[matches[0]]}'?" if matches else ""


@dataclass(frozen=True)
class Url:
    """A split backend URL; ``target`` (between ``://`` and ``?``) and option values are unquoted."""

    text: str
    direction: str
    scheme: str
    target: str
    options: Mapping[str, str] = field(default_factory=dict)

    def fail(self, problem: str, forms: Sequence[UrlForm | str]) -> ConfigError:
        """The error for ``problem`` with this URL, ending with the expected form(s)."""
        return _error(self.direction, self.text, problem, forms)


def _error(direction: str, text: str, problem: str, forms: Sequence[UrlForm | str]) -> ConfigError:
    expected = " or ".join(str(form) for form in forms)
    shown = printable(text if len(text) <= _SHOWN_CHARS else text[:_SHOWN_CHARS] + "...")
    return ConfigError(f"{direction} URL '{shown}': {problem}; expected {expected}")


def _control_character(texts: Sequence[str]) -> str | None:
    """The first control character (NUL, newline, escape...) in ``texts``, or None."""
    return next((char for text in texts for char in text if unicodedata.category(char) == "Cc"), None)


def parse_url(text: str, direction: str, schemes: Mapping[str, Sequence[UrlForm | str]]) -> Url:
    """Split ``text`` (an ``input`` or ``output`` URL, as ``direction`` says).

    ``schemes`` maps each known scheme to the forms it accepts (for the messages).
    Raises ConfigError when ``text`` is longer than MAX_URL_CHARS, has no ``scheme://``,
    names an unknown scheme (with a did-you-mean hint and every valid form), has a
    malformed query, an option without a value or an option given twice, or holds a
    control character (a NUL byte, a newline; also written ``%00``) anywhere.
    """
    every_form = [form for forms in schemes.values() for form in forms]
    if len(text) > MAX_URL_CHARS:
        raise _error(direction, text, f"{len(text):,} characters long, more than the {MAX_URL_CHARS:,} a URL may have",
                     every_form)
    scheme, separator, rest = text.partition("://")
    if not separator or not scheme:
        raise _error(direction, text, "not a URL (no 'scheme://')", every_form)
    if scheme not in schemes:
        known = ", ".join(f"{name}://" for name in schemes)
        problem = f"unknown scheme '{scheme}'{did_you_mean(scheme, list(schemes))} (known: {known})"
        raise _error(direction, text, problem, every_form)
    target, _, query = rest.partition("?")
    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query))
    except ValueError:
        raise _error(direction, text, f"malformed options '{query}' (write name=value&name=value)",
                     schemes[scheme]) from None
    options: dict[str, str] = {}
    for name, value in pairs:
        if name in options:
            raise _error(direction, text, f"option '{name}' given twice", schemes[scheme])
        if not value:
            raise _error(direction, text, f"option '{name}' has no value", schemes[scheme])
        options[name] = value
    target = unquote(target)
    bad = _control_character([text, target, *options, *options.values()])
    if bad is not None:
        raise _error(direction, text, f"holds the control character {printable(bad)} (after unquoting); "
                     "URLs, paths and option values must be printable text", schemes[scheme])
    return Url(text=text, direction=direction, scheme=scheme, target=target, options=options)


@dataclass(frozen=True)
class Option:
    """One URL option: ``name``, the value used when it is absent, and its parser."""

    name: str
    default: Any
    parse: Parser

    def example(self) -> str:
        """``name=default`` as a URL would write it."""
        return f"{self.name}={_format(self.default)}"


def _format(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, tuple):
        return ",".join(_format(item) for item in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass(frozen=True)
class UrlForm:
    """One accepted URL shape; ``str(form)`` is the example shown in messages.

    ``target`` is what goes between ``://`` and ``?``: the word that selects the form
    (``swipe``) or a placeholder for a free part (``/path/out.wav``); the backend
    module compares it, the form only shows it.
    """

    scheme: str
    target: str = ""
    options: tuple[Option, ...] = ()

    def __str__(self) -> str:
        query = "&".join(option.example() for option in self.options)
        return f"{self.scheme}://{self.target}" + (f"?{query}" if query else "")

    def read(self, url: Url) -> dict[str, Any]:
        """Every option's value (the default when absent), checked.

        Raises ConfigError naming the option for an unknown option (did-you-mean and
        the valid options) or a value its parser rejects.
        """
        names = [option.name for option in self.options]
        for name in url.options:
            if name not in names:
                valid = ", ".join(names) if names else "none"
                raise url.fail(f"unknown option '{name}'{did_you_mean(name, names)} (options: {valid})", [self])
        values: dict[str, Any] = {}
        for option in self.options:
            if option.name not in url.options:
                values[option.name] = option.default
                continue
            given = url.options[option.name]
            try:
                values[option.name] = option.parse(given)
            except ValueError as error:
                raise url.fail(f"option {option.name}: {error}, got '{given}'", [self]) from None
        return values


def number(low: float = -math.inf, *, low_closed: bool = True, high: float = math.inf,
           allow_inf: bool = False) -> Parser:
    """A parser of a finite number in ``[low, high]`` (``(low, high]`` unless ``low_closed``).

    With ``allow_inf``, ``inf`` is accepted too (besides the finite numbers up to ``high``).
    """
    bound = f"{'>=' if low_closed else '>'} {low:g}" if low > -math.inf else ""
    if high < math.inf:
        bound = f"in {'[' if low_closed else '('}{low:g}, {high:g}]"
    expected = "a number" + (f" {bound}" if bound else "") + (" or inf" if allow_inf else "")

    def parse(text: str) -> float:
        try:
            value = parse_decimal(text, allow_inf)
        except ValueError:
            raise ValueError(f"must be {expected}") from None
        if allow_inf and value == math.inf:
            return value
        above = value >= low if low_closed else value > low
        if not (math.isfinite(value) and above and value <= high):
            raise ValueError(f"must be {expected}")
        return value

    return parse


def count(low: int = 0, high: int | None = None) -> Parser:
    """A parser of a whole number ``>= low`` (and ``<= high`` when given)."""
    expected = f"a whole number >= {low}" if high is None else f"a whole number in [{low}, {high}]"

    def parse(text: str) -> int:
        try:
            value = parse_whole(text)
        except ValueError:
            raise ValueError(f"must be {expected}") from None
        if value < low or (high is not None and value > high):
            raise ValueError(f"must be {expected}")
        return value

    return parse


def flag(text: str) -> bool:
    """Parse ``0`` or ``1``; ValueError otherwise."""
    if text not in ("0", "1"):
        raise ValueError("must be 0 or 1")
    return text == "1"


def point(text: str) -> tuple[float, float]:
    """Parse ``x,y`` (two finite numbers); ValueError otherwise."""
    parts = text.split(",")
    try:
        values = tuple(parse_decimal(part) for part in parts)
    except ValueError:
        values = ()
    if len(values) != 2 or not all(math.isfinite(value) for value in values):
        raise ValueError("must be two numbers x,y")
    return values
