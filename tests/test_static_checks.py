"""Static checks over the repository, as part of the suite (tests/run): ruff with the project's rules
(pyproject.toml ``[tool.ruff.lint]``) and mypy over the package (``[tool.mypy]``). Both come with the
test extras, so a missing one is an installation error, not a skip."""

from __future__ import annotations

import subprocess
import sys

from conftest import REPO_ROOT


def _run(*tool: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *tool], cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_finds_nothing() -> None:
    done = _run("ruff", "check", "--no-cache", ".")
    assert done.returncode == 0, done.stdout + done.stderr


def test_mypy_finds_nothing() -> None:
    done = _run("mypy", "--no-incremental", "--cache-dir=/dev/null")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("Success: no issues found")
