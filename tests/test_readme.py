"""The README's Python snippets run as written, from the repository, and print what their comments say."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from conftest import REPO_ROOT

BLOCKS = re.findall(r"```python\n(.*?)```", (REPO_ROOT / "README.md").read_text(), re.S)


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, timeout=300)


def test_the_readme_has_its_three_python_snippets() -> None:
    assert len(BLOCKS) == 3


#: What the physics snippet prints, line by line; each is also the comment on its line in the README.
PHYSICS_PRINTS = ("0.2997", "2.232e-06", "5.08e-08 m/V, 0.0003295 W/V^2, tau 1.55 ms",
                  "[0.00000000e+00 6.01509429e-08 1.17927744e-07]", "[]")


def test_the_physics_snippet_prints_what_its_comments_say() -> None:
    done = _run(BLOCKS[0])
    assert done.returncode == 0, done.stderr
    assert tuple(done.stdout.splitlines()) == PHYSICS_PRINTS
    comments = [line.split("  # ", 1)[1] for line in BLOCKS[0].splitlines() if "  # " in line]
    assert all(any(comment.startswith(printed) for comment in comments) for printed in PHYSICS_PRINTS)


@pytest.mark.parametrize("index", [1, 2])
def test_the_rendering_snippets_run_without_audio_hardware(index: int) -> None:
    done = _run(BLOCKS[index])
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
