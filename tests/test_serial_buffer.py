"""``serial://...?buffer_ms=``: every buffer the URL and the amplifier accept plays the texture at its levels.

The streamer renders ``buffer_ms`` ahead of the sample the amplifier plays, and the Renderer stamps a
finger sample with the stream time of the sample at the output (its ``now_s``; the virtual run
stamps the same way). The kernel's finger watchdog judges a finger's age when its block is rendered
(the block's lead, ``cfg[CFG_OUTPUT_LEAD_S]``, off its age), so a lead longer than the 50 ms
watchdog no longer takes a sliding finger for a lost one (it played 0 V at ``buffer_ms=60``), and a
finger that stops reporting still ramps the drive down ``watchdog_ms`` after its last sample, as
rendered. On the virtual link and clock: deterministic.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import yaml
from virtual_serial import DEVICE, GRATING, VirtualRun

from tpad_rt.amp.virtual_link import VirtualLink
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import layout
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.render import render_block
from tpad_rt.physics.friction import relative_friction
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.texture import load_compiled

#: The emulator's buffer (1024 samples at 16 kHz) less one 0.5 ms frame: the largest buffer_ms its handshake takes.
LARGEST_MS = 63.5


@functools.cache
def levels(buffer_ms: float) -> tuple[float, float, float, int, int, int]:
    """A 1.2 s swipe at 100 mm/s with ``buffer_ms``: the friction the emulated plate gave (1st and 99th percentile
    over the middle of the swipe), the 99th percentile of the applied envelope (V) there, the underruns, the
    blocks the kernel rendered with the finger taken as gone (FLAG_WATCHDOG) while it slid, and the frames whose
    lead was above the bound the streamer set (AmpLink.lead_bound_s)."""
    link = VirtualLink.emulating(DEVICE)
    run = VirtualRun(link, query=f"buffer_ms={buffer_ms:g}").start()
    run.swipe(1.2, speed_mm_s=100.0, x0_mm=10.0)
    telemetry = run.pipeline.drain_telemetry()
    assert run.stop() is None
    recording = link.recording()
    fed = np.flatnonzero(recording["index"] >= 0)
    middle = fed[len(fed) // 10: -len(fed) // 10]
    friction = relative_friction(recording["plate_amplitude_um"][middle] * 1e-6, DEVICE.carrier_hz, 0.1, DEVICE.mu0,
                                 DEVICE.poisson, DEVICE.psi_star)
    sliding = (telemetry["t"] > 0.1) & (telemetry["t"] < 1.1)
    gone = np.count_nonzero(telemetry["saturated"][sliding].astype(np.int64) & layout.FLAG_WATCHDOG)
    return (float(np.percentile(friction, 1)), float(np.percentile(friction, 99)),
            float(np.percentile(np.abs(recording["envelope_v"][middle]), 99)), run.stats()["amp_underruns"], gone,
            int(run.table.stats[tab.STAT_LEAD_OVER]))


@pytest.mark.parametrize("buffer_ms", [2.0, 40.0, 60.0, LARGEST_MS])
def test_every_buffer_the_amplifier_takes_plays_the_grating_at_its_levels(buffer_ms: float) -> None:
    grating = yaml.safe_load(GRATING.read_text())["friction"]
    low, high, peak_v, underruns, gone, lead_over = levels(buffer_ms)
    reference = levels(2.0)
    assert gone == 0, f"the finger was taken as gone in {gone} blocks while it slid"
    assert lead_over == 0, "the streamer's bound on its lead is below a lead it had"
    assert underruns == 0
    assert low == pytest.approx(grating["low"], rel=0.02) and high == pytest.approx(grating["high"], rel=0.02)
    assert (low, high, peak_v) == pytest.approx(reference[:3], rel=0.005)


def test_a_buffer_past_the_amplifier_s_is_refused_in_one_line() -> None:
    link = VirtualLink.emulating(DEVICE)
    with pytest.raises(ConfigError, match=r"buffer_ms=63\.6 is more than the amplifier's buffer holds at 16000 Hz "
                                        r"\(at most 63\.5 ms\)"):
        VirtualRun(link, query="buffer_ms=63.6").start()


@pytest.mark.parametrize("buffer_ms", [2.0, 60.0])
def test_a_finger_that_stops_reporting_ramps_down_a_watchdog_after_its_last_sample_plus_the_lead(
        buffer_ms: float) -> None:
    options = RenderOptions()
    link = VirtualLink.emulating(DEVICE)
    run = VirtualRun(link, query=f"buffer_ms={buffer_ms:g}").start()
    run.swipe(0.5, speed_mm_s=100.0, x0_mm=10.0)
    last_push_s = run.clock.now_ns() * 1e-9 - 0.002  # the swipe's samples come every 2 ms up to its end
    run.run_for(0.3)  # no sample: the finger stopped reporting, without a lift
    recording = link.recording()  # on the amplifier's clock, which is the host's here (no drift)
    driven = np.flatnonzero(np.abs(recording["envelope_v"]) > 0)
    silent_after_ms = (recording["t_s"][driven[-1]] - last_push_s) * 1e3
    # The gate closes watchdog_ms after the last sample on the render clock; the ramp then plays buffer_ms later.
    earliest_ms = options.watchdog_ms + buffer_ms
    assert earliest_ms <= silent_after_ms <= earliest_ms + options.ramp_ms + 2.0
    assert run.stop() is None


def test_the_kernel_judges_a_finger_s_age_when_its_block_is_rendered_not_when_it_plays() -> None:
    options = RenderOptions(control_interval=1)  # a control step at every sample
    pipeline = Pipeline(DEVICE, load_compiled(GRATING), 16000, options=options, envelope_output=True)
    pipeline.start()
    out = np.zeros(16, dtype=np.float32)
    while pipeline.time_s < 0.2:
        pipeline.push_finger(pipeline.time_s, 20.0 + 100.0 * pipeline.time_s, 20.0, 0.5)
        pipeline.render(out)
    pushed_s = pipeline.last_time_s
    cfg = pipeline.arrays.cfg

    def flags_at(age_s: float, lead_s: float) -> int:
        """The FLAG_* bits of a block rendered ``age_s`` after the last sample, ``lead_s`` ahead of the output."""
        state = pipeline.arrays.state.copy()
        cfg[layout.CFG_OUTPUT_LEAD_S] = lead_s
        index = round((pushed_s + age_s) * 16000)
        render_block(np.zeros(1, dtype=np.float32), index, *pipeline.arrays)
        flags = int(pipeline.arrays.telem[(pipeline.arrays.telem_count[0] - 1) % len(pipeline.arrays.telem),
                                          layout.TEL_FLAGS])
        pipeline.arrays.state[:] = state
        return flags

    watchdog_s = options.watchdog_ms * 1e-3
    assert not flags_at(watchdog_s + 0.06 - 0.001, 0.06) & layout.FLAG_WATCHDOG
    assert flags_at(watchdog_s + 0.06 + 0.001, 0.06) & layout.FLAG_WATCHDOG
    assert flags_at(watchdog_s + 0.001, 0.0) & layout.FLAG_WATCHDOG
    # A lead out of its range (a corrupt cfg) counts as none: the watchdog is never stretched past MAX_OUTPUT_LEAD_S.
    for bad in (np.nan, -0.01, layout.MAX_OUTPUT_LEAD_S * 2):
        assert flags_at(watchdog_s + 0.001, bad) & layout.FLAG_WATCHDOG
