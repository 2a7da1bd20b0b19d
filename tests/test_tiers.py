"""The test tiers stay what docs/testing.md says: at most MAX_REALTIME_ITEMS tests judge time on the host's
clock (marked ``realtime``), and no test retries itself."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

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


def _retry_loops(path: Path) -> list[str]:
    """``for attempt in range(...)``-style loops (a loop variable named attempt, try or retry) in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.For) and isinstance(node.target, ast.Name) and \
                node.target.id.lower().strip("_") in {"attempt", "attempts", "try", "tries", "retry", "retries"}:
            found.append(f"{path.name}:{node.lineno}")
    return found


def test_no_test_retries_itself() -> None:
    assert [loop for path in sorted(TESTS.glob("*.py")) for loop in _retry_loops(path)] == []


def test_the_retry_check_sees_a_retry_loop(tmp_path: Path) -> None:
    sample = tmp_path / "sample.py"
    sample.write_text("def test_x():\n    for attempt in range(3):\n        pass\n")
    assert _retry_loops(sample) == ["sample.py:2"]
