"""A bogus output delay never stretches the finger watchdog: the callback takes a block's reported delay
(PortAudio's time info; the serial streamer's, through the same callback) within the bound its driver set
(CallbackTable.set_lead_bound_s), and counts the blocks it reported more, or not a number.

The native callback called from Python on blocks of a pipeline, with the time info a broken backend might
give: deterministic (the kernel judges ages on stream time, not on the host's clock).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tpad_rt.cli.play import lead_over_line
from tpad_rt.device import Device
from tpad_rt.drivers.audio_callback import lead_bound_s
from tpad_rt.kernel import layout
from tpad_rt.kernel import table as tab
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
RATE_HZ = 16000
BLOCK = 32  # 2 ms blocks
#: The lead the output can honestly have (s): a serial amplifier's 10 ms target fill and a frame, say.
BOUND_S = 0.010
WATCHDOG_S = RenderOptions().watchdog_ms * 1e-3


def closes_after_s(dac_delay_s: float) -> tuple[float, CallbackTable]:
    """Stream seconds from the last finger sample to the first block the gate is closed in, when every block
    reports ``dac_delay_s``; the finger slides for 0.2 s, stamped with the sample at the output (the block's
    first sample less the honest lead), then stops reporting."""
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), RATE_HZ, envelope_output=True)
    pipeline.start()
    table = CallbackTable(pipeline.arrays, pipeline.texture)
    table.set_lead_bound_s(BOUND_S)
    out = np.zeros(BLOCK, dtype=np.float32)
    last_s = 0.0
    while table.next_sample / RATE_HZ < 0.2:
        last_s = max(table.next_sample / RATE_HZ - BOUND_S, 0.0)
        pipeline.push_finger(last_s, 20.0 + 100.0 * last_s, 20.0, 0.5)
        table.call(out, dac_delay_s=dac_delay_s)
        assert not int(pipeline.last_telemetry_row()["saturated"]) & layout.FLAG_WATCHDOG
    while table.next_sample / RATE_HZ < 2.0:
        start_s = table.next_sample / RATE_HZ
        table.call(out, dac_delay_s=dac_delay_s)
        if int(pipeline.last_telemetry_row()["saturated"]) & layout.FLAG_WATCHDOG:
            return start_s - last_s, table
    raise AssertionError("the gate never closed")


@pytest.mark.parametrize("dac_delay_s", [1e9, np.inf, np.nan, BOUND_S + 0.2], ids=["1e18ns", "inf", "nan", "bound+0.2s"])
def test_a_delay_above_the_bound_is_taken_as_the_bound_and_counted(dac_delay_s: float) -> None:
    closed_s, table = closes_after_s(dac_delay_s)
    assert WATCHDOG_S + BOUND_S - BLOCK / RATE_HZ <= closed_s <= WATCHDOG_S + BOUND_S + BLOCK / RATE_HZ
    blocks = table.recent_blocks()
    assert table.stats[tab.STAT_LEAD_OVER] == len(blocks) > 0
    assert np.all(blocks[:, tab.BLOCK_DAC_DELAY_NS] == round(BOUND_S * 1e9))


def test_a_negative_delay_is_no_lead_and_not_counted() -> None:
    closed_s, table = closes_after_s(-1e-9)
    assert WATCHDOG_S - BLOCK / RATE_HZ <= closed_s <= WATCHDOG_S + BLOCK / RATE_HZ
    assert table.stats[tab.STAT_LEAD_OVER] == 0
    assert not table.recent_blocks()[:, tab.BLOCK_DAC_DELAY_NS].any()


def test_an_honest_delay_within_the_bound_is_taken_as_reported() -> None:
    closed_s, table = closes_after_s(BOUND_S)
    assert WATCHDOG_S + BOUND_S - BLOCK / RATE_HZ <= closed_s <= WATCHDOG_S + BOUND_S + BLOCK / RATE_HZ
    assert table.stats[tab.STAT_LEAD_OVER] == 0


def test_a_table_no_driver_bounded_takes_no_lead() -> None:
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), RATE_HZ, envelope_output=True)
    table = CallbackTable(pipeline.arrays, pipeline.texture)
    assert table.lead_bound_s == 0.0
    table.set_lead_bound_s(np.nan)
    assert table.lead_bound_s == 0.0
    table.set_lead_bound_s(5.0)
    assert table.lead_bound_s == layout.MAX_OUTPUT_LEAD_S
    assert table.copy().lead_bound_s == layout.MAX_OUTPUT_LEAD_S


def test_an_audio_stream_s_bound_is_its_reported_latency_and_a_block() -> None:
    assert lead_bound_s(0.02, 256, 48000) == pytest.approx(0.02 + 256 / 48000)
    assert lead_bound_s(np.nan, 256, 48000) == pytest.approx(256 / 48000)
    assert lead_bound_s(-1.0, 256, 48000) == pytest.approx(256 / 48000)
    assert lead_bound_s(1e9, 256, 48000) == layout.MAX_OUTPUT_LEAD_S


def test_play_says_once_in_its_summary_when_a_delay_was_above_the_bound() -> None:
    assert lead_over_line(3, 10.0, "callback", "DAC") == (
        "the host reported a delay from callback to DAC above the 10.00 ms the output can have (or not a number) for "
        "3 callbacks: the finger watchdog took 10.00 ms for them")
