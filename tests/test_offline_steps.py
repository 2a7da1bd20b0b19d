"""OfflineRender renders several blocks per step (reading the input and draining the telemetry once per
step): the result must be exactly what rendering one block per step gives."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tpad_rt import offline
from tpad_rt.device import Device
from tpad_rt.inputs import open_input
from tpad_rt.felt import texture_at_finger as felt
from tpad_rt.offline import OfflineRender, RenderResult
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

TEXTURES = Path(__file__).resolve().parents[1] / "textures"
RATE_HZ = 192000


def _render(texture: str, url: str, block: int, input_s: float, stop_after_blocks: int | None = None
            ) -> tuple[RenderResult, list[int]]:
    """Render; the blocks done after each step; stop following the input after ``stop_after_blocks``."""
    device = Device.default()
    pipeline = Pipeline(device, load_compiled(TEXTURES / texture), fs_hz=RATE_HZ)
    steps = []
    with open_input(url) as source:
        render = OfflineRender(pipeline, source, [SimOutput(device, RATE_HZ)], block_frames=block, input_s=input_s,
                               tail_s=0.01, keep_drive=True)
        while not render.done:
            render.step()
            steps.append(render.blocks_done)
            if stop_after_blocks is not None and render.blocks_done >= stop_after_blocks:
                render.stop_early()
                stop_after_blocks = None
    return render.result(), steps


@pytest.mark.parametrize(("texture", "url", "block", "input_s", "stop_after"), [
    ("grating.yaml", "scripted://swipe?speed_mm_s=100", 64, 0.2, None),
    ("bumps_grid.yaml", "scripted://circle?speed_mm_s=150", 37, 0.15, None),
    # stopped early at a step boundary
    ("temporal_pulse.yaml", "scripted://swipe?speed_mm_s=80&back_and_forth=1&repeat=0", 16, 0.1, 192),
])
def test_many_blocks_per_step_render_what_one_block_per_step_renders(
        monkeypatch: pytest.MonkeyPatch, texture: str, url: str, block: int, input_s: float,
        stop_after: int | None) -> None:
    monkeypatch.setattr(offline, "STEP_BLOCKS", 32)
    chunked, steps = _render(texture, url, block, input_s, stop_after)
    assert max(np.diff([0, *steps])) == offline.STEP_BLOCKS  # several blocks per step were rendered
    monkeypatch.setattr(offline, "STEP_BLOCKS", 1)
    single, _ = _render(texture, url, block, input_s, stop_after)
    assert single.drive is not None and chunked.drive is not None
    assert np.array_equal(single.drive, chunked.drive)
    assert single.blocks.keys() == chunked.blocks.keys()
    for name in single.blocks:
        assert np.array_equal(single.blocks[name], chunked.blocks[name], equal_nan=True), name
    assert np.array_equal(single.finger, chunked.finger)
    assert np.abs(chunked.drive).max() > 0.1  # something was rendered


def test_a_step_ends_where_the_input_ends(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(offline, "STEP_BLOCKS", 32)
    block, input_s = 64, 0.1  # 300 input blocks: not a multiple of STEP_BLOCKS
    _, steps = _render("grating.yaml", "scripted://swipe?speed_mm_s=100", block, input_s)
    assert int(np.ceil(input_s * RATE_HZ / block)) in steps


def test_the_texture_under_the_finger_is_computed_once_per_result_and_texture(monkeypatch: pytest.MonkeyPatch) -> None:
    result, _ = _render("grating.yaml", "scripted://swipe?speed_mm_s=100", 64, 0.05)
    grating, other = load_compiled(TEXTURES / "grating.yaml"), load_compiled(TEXTURES / "temporal_pulse.yaml")
    calls = []
    monkeypatch.setattr(offline, "texture_at_finger", lambda *args: calls.append(args) or felt(*args))
    first = offline.texture_under_finger(result, grating)
    assert offline.texture_under_finger(result, grating) is not None and len(calls) == 1
    again = offline.texture_under_finger(result, grating)
    assert again[0] is first[0] and again[1] is first[1] and not first[0].flags.writeable
    assert np.array_equal(first[0], felt(result.finger, grating, result.blocks["t"] + 32 / RATE_HZ)[0])
    offline.texture_under_finger(result, other)  # another texture: computed for it
    assert len(calls) == 2
