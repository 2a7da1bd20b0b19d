"""The test tiers stay what docs/testing.md says: at most MAX_REALTIME_ITEMS tests judge time on the host's
clock (marked ``realtime``), and no test retries itself."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
#: The real-time smoke tier's ceiling (test items: each parametrised case counts).
MAX_REALTIME_ITEMS = 30


def test_at_most_thirty_test_items_are_marked_realtime() -> None:
    done = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", "realtime", "-p",
                           "no:cacheprovider", str(TESTS)], cwd=TESTS.parent, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode in (0, 5), done.stdout[-2000:] + done.stderr[-2000:]  # 5: none collected
    items = [line for line in done.stdout.splitlines() if "::" in line]
    assert len(items) <= MAX_REALTIME_ITEMS, "\n".join(items)


_RETRY_NAMES = {"attempt", "attempts", "try", "tries", "retry", "retries"}


def _retry_loops(path: Path) -> list[str]:
    """The places in ``path`` that run a test again on failure: a loop over attempts (a loop variable named
    attempt, try or retry), a loop whose ``try`` swallows an AssertionError and goes round again, or a rerun
    marker (``flaky``, ``reruns``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.For) and isinstance(node.target, ast.Name) and \
                node.target.id.lower().strip("_") in _RETRY_NAMES:
            found.append(f"{path.name}:{node.lineno}")
        elif isinstance(node, (ast.For, ast.While)) and any(
                _swallows_assertion(inner) for inner in ast.walk(node) if isinstance(inner, ast.Try)):
            found.append(f"{path.name}:{node.lineno}")
        elif isinstance(node, (ast.Name, ast.Attribute, ast.keyword)) and \
                (getattr(node, "id", None) or getattr(node, "attr", None) or getattr(node, "arg", None)) in (
                    "flaky", "reruns"):
            found.append(f"{path.name}:{getattr(node, 'lineno', 0)}")
    return found


def _swallows_assertion(node: ast.Try) -> bool:
    """Whether a handler of ``node`` catches AssertionError (by name) and carries on."""
    for handler in node.handlers:
        names = [n.id for n in ast.walk(handler.type) if isinstance(n, ast.Name)] if handler.type else []
        if "AssertionError" in names and not any(isinstance(n, ast.Raise) for n in ast.walk(handler)):
            return True
    return False


def test_no_test_retries_itself() -> None:
    assert [loop for path in sorted(TESTS.glob("*.py")) for loop in _retry_loops(path)] == []


@pytest.mark.parametrize("source, caught", [
    ("def test_x():\n    for attempt in range(3):\n        pass\n", True),
    ("def test_x():\n    while True:\n        try:\n            check()\n            break\n"
     "        except AssertionError:\n            continue\n", True),
    ("@pytest.mark.flaky(reruns=3)\ndef test_x():\n    pass\n", True),
    ("def test_x():\n    for k in range(3):\n        try:\n            check(k)\n"
     "        except AssertionError as error:\n            raise RuntimeError(k) from error\n", False),
    ("def test_x():\n    for sample in samples:\n        assert sample > 0\n", False),
])
def test_the_retry_check_sees_a_retry_and_nothing_else(tmp_path: Path, source: str, caught: bool) -> None:
    sample = tmp_path / "sample.py"
    sample.write_text(source)
    assert bool(_retry_loops(sample)) is caught
