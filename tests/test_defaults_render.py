"""Every shipped texture renders at play's default input: the guard that a new texture ships tuned.

``tpad-rt play NAME`` without a display swipes back and forth at the finger the texture's file
recommends (its ``finger``: play's :func:`~tpad_rt.cli.play.auto_swipe`). Here each texture is
rendered offline, as ``tpad-rt render`` does, on the simulated plate for the 2 s of
``play NAME --duration 2``, on the default device and on the same device with its standing wave
(``examples/devices/SLG_0.56_standing_wave.yaml``), and judged as play judges it (felt.departures,
DEPARTURE_TOLERANCE_MU): at most 5 % of the touching blocks may depart from the texture under the
finger. Deterministic (the offline loop waits for no clock); about 0.3 s a render once compiled.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.cli.play import auto_swipe
from tpad_rt.cli.render import add_session_arguments, judge_departures, open_session
from tpad_rt.config import load_texture
from tpad_rt.kernel.layout import FLAG_WATCHDOG
from tpad_rt.shipped import texture_names

REPO = Path(__file__).resolve().parents[1]
STANDING_WAVE = REPO / "examples" / "devices" / "SLG_0.56_standing_wave.yaml"
#: The most departed blocks, as a share of the touching ones, a shipped texture may show at its default input.
MAX_DEPARTED = 0.05
#: Seconds of input: ``play NAME --duration 2``.
PLAY_S = 2.0


def departed_share(texture: str, input_url: str, device: Path | None) -> float:
    """The share of touching blocks whose simulated friction departs from the texture under the finger, rendering
    ``texture`` for ``input_url`` over PLAY_S seconds on ``device`` (the default device when None)."""
    parser = argparse.ArgumentParser()
    add_session_arguments(parser)
    args = parser.parse_args([texture, "--input", input_url, "--duration", str(PLAY_S),
                              *(["--device", str(device)] if device else [])])
    with contextlib.ExitStack() as stack:
        session = open_session(args, stack, keep_drive=False)
        while not session.render.done:
            session.render.step()
    result = session.render.result()
    judge_departures(result, session.metadata, session.render.pipeline.texture)
    touching = (result.blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0
    assert np.count_nonzero(touching) > 0.9 * PLAY_S * 192000 / 64  # the swipe touches all along
    return float(np.count_nonzero(result.blocks["departed"]) / np.count_nonzero(touching))


@pytest.mark.parametrize("device", [None, STANDING_WAVE], ids=["plain", "standing_wave"])
@pytest.mark.parametrize("name", texture_names())
def test_each_shipped_texture_renders_at_its_recommended_finger(name: str, device: Path | None) -> None:
    finger = load_texture(name).finger
    assert finger is not None, f"{name}: state the finger it is designed for (finger: {{speed_mm_s, force_n}})"
    share = departed_share(name, auto_swipe(finger), device)
    assert share <= MAX_DEPARTED, f"{name} at {finger.speed_mm_s:g} mm/s: {100 * share:.1f} % of blocks departed"


def test_the_judge_fails_a_texture_swiped_faster_than_the_device_renders() -> None:
    """The guard can fail: bumps_grid at the 100 mm/s play took before textures stated a finger departs in
    nearly every block (the drive saturates at 40 V short of the slippery ground's 0.5)."""
    assert departed_share("bumps_grid", "scripted://swipe?speed_mm_s=100&repeat=0&back_and_forth=1", None) > 0.9
