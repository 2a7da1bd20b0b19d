"""The native audio callback called from Python (no sound card): same samples as Pipeline.render,
channel layout, statistics and block records, texture slots."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpad_rt.device import Device
from tpad_rt.kernel import callback as cb
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.layout import CFG_TEXTURE_T0_S
from tpad_rt.pipeline import Pipeline
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

TEXTURES = Path(__file__).resolve().parents[1] / "textures"
RATE_HZ = 192000


def started_pipeline(texture: str = "grating.yaml") -> Pipeline:
    """A running pipeline with a 0.2 s swipe pushed ahead."""
    pipeline = Pipeline(Device.default(), load_compiled(TEXTURES / texture), RATE_HZ)
    pipeline.start()
    for k in range(200):
        pipeline.push_finger(k * 1e-3, 10.0 + 0.05 * k, 20.0)
    return pipeline


def test_callback_renders_what_pipeline_render_renders_into_its_channel() -> None:
    reference, shared = started_pipeline(), started_pipeline()
    table = CallbackTable(shared.arrays, shared.texture, channels=3, channel=1)
    out = np.full((100, 3), np.nan, dtype=np.float32)  # PortAudio may hand over any size
    expected = np.zeros(100, dtype=np.float32)
    for _ in range(300):
        table.call(out)
        reference.render(expected)
        assert np.array_equal(out[:, 1], expected)
        assert not out[:, [0, 2]].any()
    assert np.abs(expected).max() > 0.1
    assert table.stats[tab.STAT_CALLBACKS] == 300 and table.stats[tab.STAT_FRAMES] == 30000
    blocks = table.recent_blocks()
    assert np.array_equal(blocks[:, tab.BLOCK_SAMPLE_INDEX], np.arange(300) * 100)
    assert np.all(blocks[:, tab.BLOCK_FRAMES] == 100) and np.all(blocks[:, tab.BLOCK_COMPUTE_NS] > 0)
    assert np.all(blocks[:, tab.BLOCK_FINGER_COUNT] == 200)
    ring = table.drive[np.arange(29900, 30000) % len(table.drive)]
    assert np.array_equal(ring, expected)


def test_blocks_longer_than_the_scratch_are_rendered_in_pieces() -> None:
    reference, shared = started_pipeline(), started_pipeline()
    table = CallbackTable(shared.arrays, shared.texture, scratch_frames=64)
    out = np.zeros(1000, dtype=np.float32)
    expected = np.zeros(1000, dtype=np.float32)
    for _ in range(20):
        table.call(out)
        reference.render(expected)
        assert np.array_equal(out, expected)


def test_texture_swap_flips_slots_and_the_texture_clock() -> None:
    shared = started_pipeline()
    table = CallbackTable(shared.arrays, shared.texture)
    out = np.zeros(64, dtype=np.float32)
    table.call(out)
    table.set_texture(load_compiled(TEXTURES / "temporal_pulse.yaml"), 0.25, running=False)
    assert table.active_slot == 1 and table.slot_t0_s[1] == 0.25
    table.call(out)
    assert shared.arrays.cfg[CFG_TEXTURE_T0_S] == 0.25
    table.set_texture(load_compiled(TEXTURES / "grating.yaml"), 0.5, running=False)
    assert table.active_slot == 0


def test_dac_sample_follows_the_newest_block() -> None:
    shared = started_pipeline()
    table = CallbackTable(shared.arrays, shared.texture)
    assert table.dac_sample(0) == 0.0
    table.call(np.zeros(64, dtype=np.float32))
    entry_ns = int(table.blocks[0, tab.BLOCK_ENTRY_NS])
    assert table.dac_sample(entry_ns) == 0.0
    assert table.dac_sample(entry_ns + 1_000_000) == RATE_HZ * 1e-3


def test_silence_callback_writes_zeros_and_counts() -> None:
    shared = started_pipeline()
    table = CallbackTable(shared.arrays, shared.texture, channels=2)
    out = np.ones(128, dtype=np.float32)
    table.call(out, cb.silence_callback)
    assert not out.any() and table.stats[tab.STAT_CALLBACKS] == 1 and table.stats[tab.STAT_FRAMES] == 64
