"""An output kind defined here, in a test module, registered at run time, plays through the Renderer.

This module is the worked example of docs/architecture.md "Adding an output kind": ``memory://NAME``
keeps the blocks it is handed in memory (a list per name), for a program to read back. It declares
its URL forms (``FORMS``), its kind (``KIND``: what it consumes, the driver that runs it, its
capabilities) and ``open_url``; :func:`tpad_rt.outputs.register_output` adds it, and no file of
tpad-rt changes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import types
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from tpad_rt.device import Device
from tpad_rt.engine import Renderer
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import (
    Capability, Consumes, Output, OutputKind, open_output, output_forms, register_output, unregister_output,
)
from tpad_rt.pipeline import RenderOptions
from tpad_rt.urls import Option, Url, UrlForm, count

# --- the output kind ------------------------------------------------------------------------------

#: ``memory://NAME?keep_blocks=N``: the blocks go to ``KEPT[NAME]``, the newest N of them.
FORMS = (UrlForm("memory", "NAME", (Option("keep_blocks", 100_000, count(1, 10_000_000)),)),)
#: DAC samples, handed over block by block by the paced driver; it also opens offline (tpad-rt render).
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", Capability.OFFLINE)
#: What each ``memory://NAME`` output was handed: NAME -> [(samples, telemetry row), ...].
KEPT: dict[str, list[tuple[npt.NDArray[np.float32], dict[str, float]]]] = {}


class MemoryOutput(Output):
    """Keeps the newest ``keep_blocks`` blocks (copies) and their telemetry rows under ``KEPT[name]``."""

    def __init__(self, name: str, keep_blocks: int, fs_hz: int):
        super().__init__(fs_hz)
        self.blocks = KEPT.setdefault(name, [])
        self.keep_blocks = keep_blocks

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        self.blocks.append((samples.copy(), dict(block)))
        del self.blocks[:-self.keep_blocks]


def open_url(url: Url, *, device: Device, fs_hz: int) -> MemoryOutput:
    """The output ``memory://NAME`` names; ConfigError without a NAME."""
    values = FORMS[0].read(url)
    if not url.target:
        raise url.fail("name the list the blocks go to, e.g. memory://run1", FORMS)
    return MemoryOutput(url.target, values["keep_blocks"], fs_hz)


# --- the tests ------------------------------------------------------------------------------------

REPO = Path(__file__).resolve().parents[1]
GRATING = str(REPO / "textures" / "grating.yaml")


@pytest.fixture
def registered() -> Iterator[None]:
    """memory:// registered for one test."""
    register_output(sys.modules[__name__])
    KEPT.clear()
    yield
    unregister_output("memory")


def _slide(renderer: Renderer, x_mm: np.ndarray, dt_s: float) -> None:
    """Push a finger at each of ``x_mm`` (y = 20 mm), ``dt_s`` apart on the stream clock, each once the stream
    has rendered up to it (waiting on the samples rendered, not on the wall clock), then lift it."""
    t0_s = renderer.now_s() + 0.01
    for k, x in enumerate(x_mm):
        renderer.push_finger(float(x), 20.0, t=t0_s + k * dt_s)
        _wait_rendered(renderer, t0_s + k * dt_s)
    renderer.lift(t=t0_s + len(x_mm) * dt_s)
    _wait_rendered(renderer, t0_s + len(x_mm) * dt_s + 0.02)


def _wait_rendered(renderer: Renderer, t_s: float) -> None:
    """Until the stream has rendered past stream time ``t_s`` (s); the run's error, if one ends it."""
    table = renderer.callback_table
    assert table is not None
    while table.next_sample < t_s * renderer.rate_hz:
        renderer.join(0.005)


def test_a_registered_output_kind_plays_through_the_renderer(registered: None) -> None:
    with Renderer(output="memory://run1?keep_blocks=1000000", texture=GRATING, rate_hz=96000,
                  block_frames=256) as renderer:
        _slide(renderer, np.linspace(20.0, 60.0, 40), 0.005)
    stats = renderer.stats()
    kept = KEPT["run1"]
    samples = np.concatenate([block for block, _ in kept])
    assert len(samples) == stats["frames"] == stats["callbacks"] * 256  # every rendered block reached the output
    assert np.all(np.isfinite(samples)) and np.abs(samples).max() <= 1.0
    volts = np.array([row["voltage_v"] for _, row in kept])
    assert volts.max() > 1.0  # the grating drove the plate while the finger slid
    assert volts.max() <= renderer.drive.max_voltage_v
    assert volts[-1] == 0.0  # and the stop ramped it to 0 before the output closed
    assert renderer.drive.source == "device file" and renderer.drive.consumes is Consumes.DAC


def test_a_registered_output_opens_offline_and_is_listed(registered: None) -> None:
    assert output_forms()["memory"] == FORMS
    with open_output("memory://offline", device=Device.default(), fs_hz=48000) as output:
        output.write(np.full(8, 0.5, dtype=np.float32), {"voltage_v": 1.0})
    assert len(KEPT["offline"]) == 1
    with pytest.raises(ConfigError, match="name the list"):
        open_output("memory://", device=Device.default(), fs_hz=48000)


def test_the_renderer_checks_a_registered_urls_options_when_it_opens_the_output(registered: None) -> None:
    renderer = Renderer(output="memory://x?keep_blocks=0", options=RenderOptions())
    with pytest.raises(ConfigError, match="option keep_blocks: must be a whole number"):
        renderer.start()
    assert not renderer.running


def test_unregistered_it_is_an_unknown_scheme() -> None:
    with pytest.raises(ConfigError, match="memory"):
        Renderer(output="memory://run1")


def test_a_taken_scheme_or_a_module_without_a_declaration_is_refused(registered: None) -> None:
    with pytest.raises(ConfigError, match="memory:// is taken"):
        register_output(sys.modules[__name__])
    shipped = types.ModuleType("fake_sim")
    shipped.FORMS = (UrlForm("sim"),)  # type: ignore[attr-defined]
    shipped.KIND = KIND  # type: ignore[attr-defined]
    shipped.open_url = open_url  # type: ignore[attr-defined]
    with pytest.raises(ConfigError, match="sim:// is taken"):
        register_output(shipped)
    bare = types.ModuleType("bare")
    with pytest.raises(ConfigError, match="FORMS: must be a non-empty tuple of UrlForm"):
        register_output(bare)
    bare.FORMS = (UrlForm("Bad Scheme"),)  # type: ignore[attr-defined]
    bare.KIND = KIND  # type: ignore[attr-defined]
    with pytest.raises(ConfigError, match="one scheme, a lower-case letter"):
        register_output(bare)
    bare.FORMS = (UrlForm("fine"),)  # type: ignore[attr-defined]
    bare.KIND = OutputKind(Consumes.DAC, "no driver here")  # type: ignore[attr-defined]
    with pytest.raises(ConfigError, match="KIND.driver: must name a driver class"):
        register_output(bare)
    bare.KIND = KIND  # type: ignore[attr-defined]  # offline, but no open_url
    with pytest.raises(ConfigError, match="must define open_url"):
        register_output(bare)
    with pytest.raises(ConfigError, match="was not registered"):
        unregister_output("sim")


def test_a_kind_naming_something_other_than_a_driver_fails_to_open(registered: None) -> None:
    module = types.ModuleType("not_a_driver")
    module.FORMS = (UrlForm("notadriver"),)  # type: ignore[attr-defined]
    module.KIND = OutputKind(Consumes.DAC, "tpad_rt.outputs.sim:SimOutput")  # type: ignore[attr-defined]
    register_output(module)
    try:
        with pytest.raises(ConfigError, match="not a tpad_rt.drivers.Driver"):
            Renderer(output="notadriver://")
    finally:
        unregister_output("notadriver")


def test_the_worked_example_in_docs_architecture_runs_as_written(tmp_path: Path) -> None:
    """docs/architecture.md "Adding an output kind": its module, saved as memory_output.py, and its program run
    in a fresh interpreter from the repository's root, as a reader would run them."""
    text = (REPO / "docs" / "architecture.md").read_text()
    module, program = re.findall(r"```python\n(.*?)```", text[text.index("### Adding an output kind"):], re.S)[:2]
    (tmp_path / "memory_output.py").write_text(module)
    (tmp_path / "program.py").write_text(program)
    done = subprocess.run([sys.executable, str(tmp_path / "program.py")], cwd=REPO, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{REPO}"}, timeout=300)
    assert done.returncode == 0, done.stderr
    blocks = int(done.stdout.split()[0])
    assert blocks > 0 and "source='device file'" in done.stdout
