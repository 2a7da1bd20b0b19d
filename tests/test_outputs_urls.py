"""Output URL dispatch (unknown schemes and options, with the expected forms) and null://."""

from __future__ import annotations

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.drivers import open_driver
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import Capability, Consumes, open_output, output_forms, output_kind
from tpad_rt.outputs.null import NullOutput
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import RenderOptions

DEVICE = Device.default()


def test_null_counts_samples() -> None:
    with open_output("null://", device=DEVICE, fs_hz=192000) as output:
        assert isinstance(output, NullOutput)
        output.write(np.zeros(64, dtype=np.float32), {})
        output.write(np.zeros(10, dtype=np.float32), {})
        assert output.samples_written == 74
        assert output.measurements() == {}


def test_sim_q_option() -> None:
    assert open_output("sim://", device=DEVICE, fs_hz=192000).q is None
    assert open_output("sim://?q=device", device=DEVICE, fs_hz=192000).q is None
    output = open_output("sim://?q=120.5", device=DEVICE, fs_hz=192000)
    assert isinstance(output, SimOutput) and output.q == 120.5


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("nul://", "unknown scheme 'nul'; did you mean 'null'? (known: sim://, wav://, null://); "
                   "expected sim://?q=device or wav:///path/out.wav or null://"),
        ("audio", "not a URL (no 'scheme://'); expected sim://?q=device or wav:///path/out.wav or null://"),
        ("sim://?Q=3", "unknown option 'Q'; did you mean 'q'? (options: q); expected sim://?q=device"),
        ("sim://?q=0.3", "option q: must be device or a number in (0.5, 1e+06], got '0.3'; expected sim://?q=device"),
        ("sim://plate", "unexpected 'plate' after sim://; expected sim://?q=device"),
        ("null://?count=1", "unknown option 'count' (options: none); expected null://"),
        ("null://x", "unexpected 'x' after null://; expected null://"),
        ("audio://?rate=48000", "audio:// plays in real time only (tpad-rt play or a Renderer), not offline; "
                                "expected sim://?q=device or wav:///path/out.wav or null://"),
        ("serial:///dev/ttyACM0", "serial:// plays in real time only (tpad-rt play or a Renderer), not offline; "
                                  "expected sim://?q=device or wav:///path/out.wav or null://"),
    ],
)
def test_url_errors(url: str, expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        open_output(url, device=DEVICE, fs_hz=192000)
    assert str(caught.value) == f"output URL '{url}': {expected}"


@pytest.mark.parametrize(
    ("url", "consumes", "capabilities", "driver"),
    [
        ("audio://", Consumes.DAC, Capability.NONE, "AudioCallbackDriver"),
        ("serial:///dev/ttyACM0", Consumes.ENVELOPE, Capability.NONE, "SerialStreamDriver"),
        ("sim://", Consumes.DAC, Capability.OFFLINE, "PacedDriver"),
        ("wav:///tmp/x.wav", Consumes.DAC, Capability.OFFLINE | Capability.WRITES_FILE, "PacedDriver"),
        ("null://", Consumes.DAC, Capability.OFFLINE, "PacedDriver"),
    ],
)
def test_every_scheme_declares_what_it_consumes_and_gets_the_driver_it_names(
        url: str, consumes: Consumes, capabilities: Capability, driver: str) -> None:
    _, kind = output_kind(url)
    assert (kind.consumes, kind.capabilities) == (consumes, capabilities)
    assert kind.driver.endswith(f":{driver}")
    made = open_driver(url, device=DEVICE, rate_hz=192000, block_frames=64, options=RenderOptions(),
                       stall_timeout_s=0.5)
    assert type(made).__name__ == driver and made.consumes is consumes
    assert set(output_forms()) == {"audio", "serial", "sim", "wav", "null"}


def test_an_envelope_output_renders_at_its_envelope_rate_in_its_frames_keeping_the_control_period() -> None:
    made = open_driver("serial:///dev/ttyACM0?envelope_hz=8000&frame_ms=1", device=DEVICE, rate_hz=192000,
                       block_frames=64, options=RenderOptions(), stall_timeout_s=0.5)
    assert (made.rate_hz, made.block_frames) == (8000, 8)
    control_period_s = RenderOptions().control_interval / 192000
    assert made.options.control_interval == max(1, round(control_period_s * 8000))
    chosen = open_driver("serial:///dev/ttyACM0?envelope_hz=8000", device=DEVICE, rate_hz=192000, block_frames=64,
                         options=RenderOptions(control_interval=3), stall_timeout_s=0.5)
    assert chosen.options.control_interval == 3  # one the caller chose is kept


def test_an_audio_url_s_rate_and_block_replace_the_renderer_s_only_when_written() -> None:
    written = open_driver("audio://?rate=48000&block=256", device=DEVICE, rate_hz=192000, block_frames=64,
                          options=RenderOptions(), stall_timeout_s=0.5)
    assert (written.rate_hz, written.block_frames) == (48000, 256)
    default = open_driver("audio://", device=DEVICE, rate_hz=96000, block_frames=32, options=RenderOptions(),
                          stall_timeout_s=0.5)
    assert (default.rate_hz, default.block_frames) == (96000, 32)
