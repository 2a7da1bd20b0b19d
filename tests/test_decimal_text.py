"""parse_decimal: plain ASCII decimals only, against Python's float, which takes more."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tpad_rt.decimal_text import parse_decimal


@pytest.mark.parametrize(("text", "value"), [
    ("1", 1.0), ("-0.5", -0.5), ("+3e4", 3e4), (".5", 0.5), ("5.", 5.0), (" 2 ", 2.0), ("1.5E-3", 1.5e-3),
    ("-0.0", -0.0), ("1e999", math.inf),
])
def test_plain_decimals_read_as_float_reads_them(text: str, value: float) -> None:
    got = parse_decimal(text)
    assert got == value and math.copysign(1.0, got) == math.copysign(1.0, value)


@pytest.mark.parametrize("text", [
    "1_000", "\u0663\u0661", "\uff13\uff11", "inf", "-inf", "nan", "infinity", "0x10", "1e", "e5", ".", "", " ",
    "1,5", "1.2.3", "--1", "1 2", "\u00a01",
])
def test_what_float_would_guess_is_refused(text: str) -> None:
    with pytest.raises(ValueError):
        parse_decimal(text)


def test_inf_only_where_allowed() -> None:
    assert parse_decimal("inf", allow_inf=True) == math.inf and parse_decimal("+inf", allow_inf=True) == math.inf
    with pytest.raises(ValueError):
        parse_decimal("-inf", allow_inf=True)


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_every_finite_float_written_by_repr_reads_back(value: float) -> None:
    assert parse_decimal(repr(value)) == value
