"""Shared pytest fixtures and the rule for missing system components.

A test that needs a system component (a JACK server, Xvfb, socat) calls
:func:`require_system`. Locally a missing component skips the test with the reason;
under ``TPAD_RT_REQUIRE_SYSTEM=1`` (CI) it fails it, so CI cannot pass by skipping.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def system_required() -> bool:
    """True when missing system components must fail tests instead of skipping them."""
    return os.environ.get("TPAD_RT_REQUIRE_SYSTEM", "") not in ("", "0")


def require_system(available: bool, what: str) -> None:
    """Skip (locally) or fail (under TPAD_RT_REQUIRE_SYSTEM=1) when ``what`` is missing."""
    if available:
        return
    message = f"{what} is not available (tests/run installs it when run as root)"
    if system_required():
        pytest.fail(message)
    pytest.skip(message)


def require_program(name: str) -> str:
    """The path of program ``name``, or skip/fail via :func:`require_system`."""
    path = shutil.which(name)
    require_system(path is not None, f"program '{name}'")
    return path  # type: ignore[return-value]


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository's top folder."""
    return REPO_ROOT
