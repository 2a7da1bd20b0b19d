"""The README's sample ``tpad-rt play`` output has the shape of a real run of its command (docs/tools/readme_sample.py
writes it; this re-runs the command and compares with the measured numbers masked), so it cannot go stale."""

from __future__ import annotations

import importlib.util
import site
import sys
from types import ModuleType

import pytest
from conftest import REPO_ROOT

from tpad_rt.cli.play import choose_input
from tpad_rt.cli.render import peak_text
from tpad_rt.config import load_texture


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
    saturated = readme[drive][readme[drive].index("; saturated "):]
    for kicks, outside_v in ((2, 17.7), (1, 17.7), (0, 37.4)):  # kicks at touch-down in most runs, not all
        kicked = [*readme]
        kicked[drive] = f"drive: {peak_text(40.0 if kicks else outside_v, 40.0, kicks, outside_v)}{saturated}"
        assert SAMPLE.shape(kicked) == SAMPLE.shape(readme), kicked[drive]
    stale = [*readme]
    stale[power] = stale[power].replace("(cap 0.8 W", "(cap 0.55 W")  # a setting no run prints: another shape
    assert "(cap 0.8 W" in readme[power] and SAMPLE.shape(stale) != SAMPLE.shape(readme)
    assert SAMPLE.shape(readme[:-1]) != SAMPLE.shape(readme)  # a line missing


def test_the_first_line_has_one_shape_with_pynput_and_without(monkeypatch: pytest.MonkeyPatch) -> None:
    """The README's run has pynput and no display; without pynput the input's reason (play's choose_input, with
    pynput out of the import system's reach) begins with what to install: one shape, as the README's text names
    both, while the rest of the reason (the finger the swipe takes) is kept."""
    readme = SAMPLE.readme_block((REPO_ROOT / "README.md").read_text())
    finger = load_texture(REPO_ROOT / "textures" / "grating.yaml").finger
    assert finger is not None
    monkeypatch.delenv("DISPLAY", raising=False)
    no_display = choose_input("auto", finger).reason
    for name in ("pynput", "Xlib"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    installed = {*site.getsitepackages(), site.getusersitepackages()}
    monkeypatch.setattr(sys, "path", [entry for entry in sys.path if entry not in installed])
    no_pynput = choose_input("auto", finger).reason
    assert no_display.startswith("no display; ") and no_pynput.startswith("no pynput for the mouse: ")
    without = readme[0].replace(f"({no_display})", f"({no_pynput})")
    assert without != readme[0], f"the README's first line names another input: {readme[0]}"
    assert SAMPLE.shape([without, *readme[1:]]) == SAMPLE.shape(readme)
    slower = without.replace(f"{finger.speed_mm_s:g} mm/s under", f"{finger.speed_mm_s / 2:g} mm/s under")
    assert slower != without and SAMPLE.shape([slower, *readme[1:]]) != SAMPLE.shape(readme)
