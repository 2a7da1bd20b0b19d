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
import threading
import types
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from test_audio_engine import wait_for_stream

from tpad_rt import outputs
from tpad_rt.device import Device
from tpad_rt.drivers.paced import PacedDriver
from tpad_rt.engine import Renderer
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import (
    Capability, Consumes, Output, OutputKind, open_output, output_forms, output_kind, register_output,
    unregister_output,
)
from tpad_rt.pipeline import RenderOptions
from tpad_rt.realtime import CallbackTable
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
    has rendered up to it (waiting on the samples rendered, not on the wall clock: wait_for_stream), then lift
    it."""
    t0_s = renderer.now_s() + 0.01
    for k, x in enumerate(x_mm):
        renderer.push_finger(float(x), 20.0, t=t0_s + k * dt_s)
        wait_for_stream(renderer, t0_s + k * dt_s)
    renderer.lift(t=t0_s + len(x_mm) * dt_s)
    wait_for_stream(renderer, t0_s + len(x_mm) * dt_s + 0.02)


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
    bare.KIND = "the paced one"  # type: ignore[attr-defined]
    with pytest.raises(ConfigError, match="KIND: must be an OutputKind"):
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


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A package installed on the path that declares three output schemes under the entry point group: one
    that works (its module copies this one's kind as ``plugged://``), one whose module does not import, one
    whose module declares another scheme."""
    (tmp_path / "plugged_output.py").write_text(
        "from tpad_rt.urls import UrlForm\n"
        f"from {__name__} import KIND, open_url as _open_memory\n"
        "FORMS = (UrlForm('plugged', 'NAME'),)\n"
        "def open_url(url, *, device, fs_hz):\n"
        "    return _open_memory(url, device=device, fs_hz=fs_hz)\n")
    dist = tmp_path / "plugged-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: plugged\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(
        "[tpad_rt.outputs]\nplugged = plugged_output\nbroken = no_such_module_anywhere\n"
        f"liar = {__name__}\nsim = plugged_output\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    outputs._installed.cache_clear()
    KEPT.clear()
    yield tmp_path
    outputs._installed.cache_clear()


def test_an_installed_package_adds_an_output_and_a_broken_one_stops_only_its_own(installed: Path) -> None:
    _, kind = output_kind("plugged://run9")
    assert kind == KIND
    with open_output("plugged://run9", device=Device.default(), fs_hz=48000) as output:
        output.write(np.zeros(4, dtype=np.float32), {})
    assert len(KEPT["run9"]) == 1
    assert output_kind("sim://")[1].driver.endswith(":PacedDriver")  # the shipped sim:// is not taken over
    with pytest.raises(ConfigError, match=r"broken://: the installed package's no_such_module_anywhere does not "
                                          r"import: No module named 'no_such_module_anywhere'"):
        output_kind("broken://")
    with pytest.raises(ConfigError, match=r"liar://: .*FORMS: its scheme is memory://, not liar://"):
        output_kind("liar://")
    with pytest.raises(ConfigError, match=r"plugged://\.\.\. \(from the installed package's plugged_output\)"):
        output_kind("pluged://")  # a typo's message lists the installed schemes without importing them
    with pytest.raises(ConfigError, match="plugged:// is taken"):
        register_output(_module_with_scheme("plugged"))


def _module_with_scheme(scheme: str) -> types.ModuleType:
    module = types.ModuleType(f"declares_{scheme}")
    module.FORMS = (UrlForm(scheme),)  # type: ignore[attr-defined]
    module.KIND = KIND  # type: ignore[attr-defined]
    module.open_url = open_url  # type: ignore[attr-defined]
    return module


def test_registry_mistakes_are_one_message() -> None:
    with pytest.raises(ConfigError, match="module 'no_such_module_anywhere' does not import"):
        register_output("no_such_module_anywhere")
    with pytest.raises(ConfigError, match="must be a module or its name, got 3"):
        register_output(3)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="driver: must name a driver class as 'module:Class'"):
        OutputKind(Consumes.DAC, Output)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="consumes: must be Consumes.DAC or Consumes.ENVELOPE"):
        OutputKind("DAC", "tpad_rt.drivers.paced:PacedDriver")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="capabilities: must be Capability flags"):
        OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", 1)  # type: ignore[arg-type]


class InterruptedDriver(PacedDriver):
    """The paced driver, interrupted (as by Ctrl-C) while it waits out the stop ramp."""

    def wait_silent(self, table: CallbackTable, ended: threading.Event) -> int:
        raise KeyboardInterrupt


def test_a_stop_interrupted_while_it_waits_still_closes_the_output(registered: None) -> None:
    module = _module_with_scheme("interrupted")
    module.KIND = OutputKind(Consumes.DAC, f"{__name__}:InterruptedDriver")  # type: ignore[attr-defined]
    register_output(module)
    try:
        renderer = Renderer(output="interrupted://run2", texture=GRATING, rate_hz=96000, block_frames=256)
        renderer.start()
        with pytest.raises(KeyboardInterrupt):
            renderer.stop()
        assert not renderer.running and renderer.driver._thread is None  # type: ignore[attr-defined]
        renderer.stop()  # again: nothing
    finally:
        unregister_output("interrupted")
