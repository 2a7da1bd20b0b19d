"""Output URL dispatch (unknown schemes and options, with the expected forms) and null://."""

from __future__ import annotations

import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import open_output
from tpad_rt.outputs.null import NullOutput
from tpad_rt.outputs.sim import SimOutput

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
    ],
)
def test_url_errors(url: str, expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        open_output(url, device=DEVICE, fs_hz=192000)
    assert str(caught.value) == f"output URL '{url}': {expected}"
