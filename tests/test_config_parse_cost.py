"""Reading a texture is linear in its size, errors included: every error's line is found in constant time
(a file of 24,000 unknown keys took 65 s when each lookup scanned the mapping), and one error lists at most
MAX_LISTED_ERRORS problems. Cost is counted in Python calls (a profile hook), never in seconds."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import pytest

from tpad_rt.config import check_file, parse_texture
from tpad_rt.config.messages import MAX_LISTED_ERRORS
from tpad_rt.errors import ConfigError
from tpad_rt.shipped import TEXTURES_DIR

SMALL_BYTES, LARGE_BYTES = 100 << 10, 1 << 20
#: A 10x larger text may cost at most this many times the calls (linear, with some slack for fixed costs).
MAX_COST_RATIO = 12.0
GRATING = {"description": "x", "kind": "grating", "period_mm": 4, "friction": {"low": 0.6, "high": 1}}


def unknown_keys_text(size_bytes: int, as_json: bool = False) -> bytes:
    """A grating texture padded to about ``size_bytes`` with unknown keys, as YAML (one per line) or JSON
    (one line)."""
    count = size_bytes // len("unknown_key_000000: 1\n")
    keys = [f"unknown_key_{index:06d}" for index in range(count)]
    if as_json:
        return json.dumps({**GRATING, **dict.fromkeys(keys, 1)}).encode()
    return ("description: x\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n" +
            "".join(f"{key}: 1\n" for key in keys)).encode()


def calls(action: Callable[[], Any]) -> tuple[int, Any]:
    """``(Python and builtin calls made by action(), the ConfigError it raised or its result)``."""
    count = 0

    def hook(frame: FrameType, event: str, arg: Any) -> None:
        nonlocal count
        count += 1

    sys.setprofile(hook)
    try:
        outcome = action()
    except ConfigError as refused:
        outcome = refused
    finally:
        sys.setprofile(None)
    return count, outcome


def inline(as_json: bool, size_bytes: int) -> Callable[[], Any]:
    text = unknown_keys_text(size_bytes, as_json)
    return lambda: parse_texture(text, "yaml", TEXTURES_DIR, [TEXTURES_DIR])


def checked(tmp_path: Path, size_bytes: int) -> Callable[[], Any]:
    path = tmp_path / f"keys_{size_bytes}.yaml"
    path.write_bytes(unknown_keys_text(size_bytes))
    return lambda: check_file(path)


@pytest.mark.parametrize("form", ["inline JSON", "check of a YAML file"])
def test_a_ten_times_larger_texture_of_unknown_keys_costs_at_most_12_times_the_calls(form: str,
                                                                                   tmp_path: Path) -> None:
    make: Callable[[int], Callable[[], Any]] = \
        (lambda size: inline(True, size)) if form == "inline JSON" else (lambda size: checked(tmp_path, size))
    small, small_outcome = calls(make(SMALL_BYTES))
    large, large_outcome = calls(make(LARGE_BYTES))
    errors = large_outcome.errors if isinstance(large_outcome, ConfigError) else large_outcome
    assert len(errors) == MAX_LISTED_ERRORS + 1, errors[-3:]
    assert large / small <= MAX_COST_RATIO, f"{small:,} calls for {SMALL_BYTES:,} bytes, {large:,} for {LARGE_BYTES:,}"


def test_many_problems_end_in_a_count_of_those_not_listed() -> None:
    with pytest.raises(ConfigError) as refused:
        inline(False, SMALL_BYTES)()
    lines = refused.value.errors
    count = SMALL_BYTES // len("unknown_key_000000: 1\n")
    assert lines[0] == "yaml: unknown_key_000000: unknown key (line 5)"
    assert lines[MAX_LISTED_ERRORS - 1] == f"yaml: unknown_key_{MAX_LISTED_ERRORS - 1:06d}: unknown key " \
        f"(line {MAX_LISTED_ERRORS + 4})"
    assert lines[-1] == f"yaml: and {count - MAX_LISTED_ERRORS:,} more problems (the first {MAX_LISTED_ERRORS} are " \
        "listed)"


def test_repeated_keys_are_capped_the_same_way() -> None:
    text = b"description: x\nkind: grating\n" + b"period_mm: 4\n" * (3 * MAX_LISTED_ERRORS)
    with pytest.raises(ConfigError) as refused:
        parse_texture(text, "yaml", TEXTURES_DIR, [TEXTURES_DIR])
    lines = refused.value.errors
    assert lines[0] == "yaml: period_mm: duplicate key (first given on line 3) (line 4)"
    assert len(lines) == MAX_LISTED_ERRORS + 1
    assert lines[-1] == f"yaml: and {2 * MAX_LISTED_ERRORS - 1:,} more problems (the first {MAX_LISTED_ERRORS} " \
        "are listed)"
