"""The README's sample ``tpad-rt play`` output has the shape of a real run of its command (docs/tools/readme_sample.py
writes it; this re-runs the command and compares with the measured numbers masked), so it cannot go stale."""

from __future__ import annotations

import importlib.util
import re
from types import ModuleType

from conftest import REPO_ROOT


def _tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("readme_sample", REPO_ROOT / "docs" / "tools" / "readme_sample.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SAMPLE = _tool()


def test_the_readme_sample_has_the_shape_of_a_real_run() -> None:
    readme = SAMPLE.readme_block((REPO_ROOT / "README.md").read_text())
    run = SAMPLE.run_sample()
    assert SAMPLE.shape(readme) == SAMPLE.shape(run), "run python docs/tools/readme_sample.py to regenerate it"


def test_a_shape_masks_measurements_and_keeps_settings_and_every_line() -> None:
    readme = SAMPLE.readme_block((REPO_ROOT / "README.md").read_text())
    assert len(readme) >= 6 and readme[0].startswith("output sim:// ")
    power = next(index for index, line in enumerate(readme) if line.startswith("power: "))
    measured = [*readme]
    measured[power] = measured[power].replace("mean 0.", "mean 9.")  # another run's figure: the same shape
    assert SAMPLE.shape(measured) == SAMPLE.shape(readme)
    drive = next(index for index, line in enumerate(readme) if line.startswith("drive: "))
    one = [*readme]
    one[drive] = re.sub(r"kicks \(\d+ blocks", "kicks (1 block", one[drive])  # a count of one, in the singular
    assert "kicks (1 block at" in one[drive] and SAMPLE.shape(one) == SAMPLE.shape(readme)
    stale = [*readme]
    stale[power] = stale[power].replace("(cap 0.8 W", "(cap 0.55 W")  # a setting no run prints: another shape
    assert "(cap 0.8 W" in readme[power] and SAMPLE.shape(stale) != SAMPLE.shape(readme)
    assert SAMPLE.shape(readme[:-1]) != SAMPLE.shape(readme)  # a line missing
    header = [readme[0].replace("(no display)", "(no pynput for the mouse: pip install 'tpad-rt[inputs]')"),
              *readme[1:]]
    assert SAMPLE.shape(header) == SAMPLE.shape(readme)  # the README's text names both reasons
