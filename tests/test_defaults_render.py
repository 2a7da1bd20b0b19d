"""Every shipped texture renders at play's default input: the guard that a new texture ships tuned.

``tpad-rt play NAME`` without a display swipes back and forth at the finger the texture's file
recommends (its ``finger``: play's :func:`~tpad_rt.cli.play.auto_swipe`). Here each texture is
rendered offline, as ``tpad-rt render`` does, on the simulated plate for the 2 s of
``play NAME --duration 2``, on the default device and on the same device with its standing wave
(``examples/devices/SLG_0.56_standing_wave.yaml``), and judged as play judges it (felt.judge_blocks,
DEPARTURE_TOLERANCE_MU): at most 5 % of the judged blocks may depart from the texture under the
finger, and the texture under the finger must change by more than that tolerance (a swipe that crosses
nothing would pass the judge without rendering the texture), and the drive may saturate in fewer than SATURATION_HINT_SHARE of the touching ones (else play's summary
says why: the hints of :mod:`tpad_rt.cli.headroom`, whose advice is checked here too). Deterministic
(the offline loop waits for no clock); about 0.15 s a render once compiled.
"""

from __future__ import annotations

import argparse
import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.cli.headroom import SATURATION_HINT_SHARE, FingerTally, hint_lines
from tpad_rt.cli.play import auto_swipe, choose_input
from tpad_rt.cli.render import add_session_arguments, open_session
from tpad_rt.config import load_texture
from tpad_rt.config.texture_schema import Finger
from tpad_rt.device import Device
from tpad_rt.felt import DEPARTURE_TOLERANCE_MU, judge_blocks
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG
from tpad_rt.offline import RenderResult, texture_under_finger
from tpad_rt.shipped import texture_names

REPO = Path(__file__).resolve().parents[1]
STANDING_WAVE = REPO / "examples" / "devices" / "SLG_0.56_standing_wave.yaml"
#: The most departed blocks, as a share of the judged ones, a shipped texture may show at its default input.
MAX_DEPARTED = 0.05
#: Seconds of input: ``play NAME --duration 2``.
PLAY_S = 2.0


@dataclass(frozen=True)
class Run:
    """An offline run of PLAY_S seconds: its blocks' finger tally and how many were judged and departed."""

    tally: FingerTally
    felt_span_mu: float  # the range of the texture's friction under the finger over the touching blocks
    judged: int  # the touching blocks where the texture under the finger is known (felt.judge_blocks, as play)
    departed: int
    departed_saturated: int

    @property
    def departed_share(self) -> float:
        """Departed blocks as a share of the judged ones (as play's summary and hints count them)."""
        return self.departed / self.judged

    @property
    def saturated_share(self) -> float:
        """Saturated blocks as a share of the touching ones."""
        return self.tally.saturated / self.tally.touching

    def hints(self, device: Device, power_cap_w: float = 0.8) -> list[str]:
        """play's hint lines for this run on ``device`` (its 40 V limit, and ``power_cap_w``, W)."""
        return hint_lines(self.tally, device, device.max_voltage_v, power_cap_w, self.judged, self.departed,
                          self.departed_saturated)


def render(texture: str, input_url: str, device: Path | None = None, *options: str) -> Run:
    """Render ``texture`` for ``input_url`` over PLAY_S seconds on ``device`` (the default device when None) with
    ``tpad-rt render``'s ``options``, and judge it as play does (felt.judge_blocks: the judged blocks are the
    touching ones where the texture under the finger is known)."""
    parser = argparse.ArgumentParser()
    add_session_arguments(parser)
    args = parser.parse_args([texture, "--input", input_url, "--duration", str(PLAY_S),
                              *(["--device", str(device)] if device else []), *options])
    with contextlib.ExitStack() as stack:
        session = open_session(args, stack, keep_drive=False)
        while not session.render.done:
            session.render.step()
    result: RenderResult = session.render.result()
    blocks, compiled = result.blocks, session.render.pipeline.texture
    judged = judge_blocks(blocks, result.finger, compiled, block_s=result.block_frames / result.fs_hz,
                          mu_floor=session.metadata["render_options"]["mu_floor"])
    tally = FingerTally()
    tally.add(blocks)
    assert tally.touching > 0.9 * PLAY_S * 192000 / 64  # the swipe touches all along
    saturated = (blocks["saturated"].astype(np.int64) & (FLAG_VOLTAGE | FLAG_POWER)) != 0
    felt_mu, known = texture_under_finger(result, compiled)
    felt_mu = felt_mu[known & ((blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0)]
    return Run(tally, float(np.ptp(felt_mu)), int(np.count_nonzero(judged.judged)),
               int(np.count_nonzero(judged.departed)), int(np.count_nonzero(judged.departed & saturated)))


@pytest.mark.parametrize("device", [None, STANDING_WAVE], ids=["plain", "standing_wave"])
@pytest.mark.parametrize("name", texture_names())
def test_each_shipped_texture_renders_at_its_recommended_finger(name: str, device: Path | None) -> None:
    finger = load_texture(name).finger
    assert finger is not None, f"{name}: state the finger it is designed for (finger: {{speed_mm_s, force_n}})"
    run = render(name, auto_swipe(finger), device)
    at = f"{name} at {finger.speed_mm_s:g} mm/s"
    assert run.departed_share <= MAX_DEPARTED, f"{at}: {100 * run.departed_share:.1f} % of blocks departed"
    assert run.saturated_share < SATURATION_HINT_SHARE, f"{at}: {100 * run.saturated_share:.1f} % saturated"
    assert run.felt_span_mu > DEPARTURE_TOLERANCE_MU, f"{at}: the swipe crosses nothing of the texture"


def test_a_texture_swiped_too_fast_departs_and_the_hint_names_a_speed_that_renders_it() -> None:
    """bumps_grid at the 100 mm/s play took before textures stated a finger: the drive saturates at 40 V short of
    the slippery ground's 0.5 wherever the finger is off the patches; the hint says so from the device model, and
    the swipe it suggests renders the texture."""
    run = render("bumps_grid", "scripted://swipe?speed_mm_s=100&repeat=0&back_and_forth=1")
    assert run.departed_share > 0.5 and run.saturated_share > 0.5
    assert run.judged < run.tally.touching  # the last blocks outlast the swipe's samples: touching, not judged
    why, departures = run.hints(Device.default())
    assert why.startswith("why saturated (")
    assert ("the texture asks for friction down to 0.50, and at 100 mm/s under 0.5 N the drive's 40 V limit lowers "
            "it to 0.63 at best (at an antinode)") in why
    assert departures.startswith("departures in ") and "of them saturated (above)" in departures
    suggested = why.split("try --input '")[1].split("'")[0]
    assert suggested == "scripted://swipe?speed_mm_s=50&force_n=0.5&repeat=0&back_and_forth=1"
    followed = render("bumps_grid", suggested)
    assert followed.departed_share <= MAX_DEPARTED and followed.hints(Device.default()) == []


def test_a_power_cap_that_binds_is_named_with_its_volts() -> None:
    run = render("grating", "scripted://swipe?speed_mm_s=60&repeat=0&back_and_forth=1", None, "--power-budget", "0.02")
    why = run.hints(Device.default(), power_cap_w=0.02)[0]
    assert "the drive's 0.02 W power cap (7.8 V at 0.5 N) lowers it to 0.95 at best" in why, why
    assert "try --input 'scripted://swipe?speed_mm_s=20&force_n=0.5" in why


@pytest.mark.parametrize(("recommended", "force_n", "url", "why"), [
    (Finger(speed_mm_s=30, force_n=0.4), None, "scripted://swipe?speed_mm_s=30&force_n=0.4&repeat=0&back_and_forth=1",
     "the texture's recommended finger: 30 mm/s under 0.4 N"),
    (None, None, "scripted://swipe?speed_mm_s=100&force_n=0.5&repeat=0&back_and_forth=1",
     "no finger in the texture's file: 100 mm/s under 0.5 N"),
    (Finger(speed_mm_s=30, force_n=0.4), 1.5, "scripted://swipe?speed_mm_s=30&force_n=1.5&repeat=0&back_and_forth=1",
     "the texture's recommended finger: 30 mm/s, under --force 1.5 N"),
])
def test_without_a_display_auto_swipes_at_the_recommended_finger(monkeypatch: pytest.MonkeyPatch,
                                                                 recommended: Finger | None, force_n: float | None,
                                                                 url: str, why: str) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    choice = choose_input("auto", recommended, force_n)
    assert choice.url == url
    assert choice.reason.endswith(f"; {why}") and choice.reason.startswith(("no display", "no pynput"))
    assert choose_input("scripted://still", recommended, force_n).url == "scripted://still"  # an explicit one wins


def test_departures_without_saturation_name_the_plates_lag_and_a_slower_finger() -> None:
    device = Device.default()
    tally = FingerTally(touching=1000, saturated=0, speed_sum_mm_s=30_000.0, force_sum_n=500.0, lowest_mu=0.6)
    assert hint_lines(tally, device, 40.0, 0.8, judged=1000, departed=50, departed_saturated=0) == []  # 5 %: fine
    (line,) = hint_lines(tally, device, 40.0, 0.8, judged=1000, departed=100, departed_saturated=3)
    assert line.startswith("departures in 10.0 % of judged blocks, more than 5 %: 3 of them saturated; ")
    (line,) = hint_lines(tally, device, 40.0, 0.8, judged=1000, departed=100, departed_saturated=0)
    tau_ms = float(device.envelope_time_constant_s(0.5)) * 1e3
    assert (f"none saturated: the plate lags the texture's changes at 30 mm/s under 0.5 N (its envelope's time "
            f"constant is {tau_ms:.2f} ms at 0.5 N); a slower finger leaves more headroom (try --input "
            "'scripted://swipe?speed_mm_s=15&force_n=0.5&repeat=0&back_and_forth=1')") in line, line


@pytest.mark.parametrize(("lowest_mu", "reach"), [
    (0.0, "no finger speed reaches 0.00 with this drive (the friction model takes a finger slower than the device's "
          "speed floor, 5 mm/s, as that fast, and there the drive lowers it to 0.05 at best)"),
    (0.05, "only a finger between the device's speed floor, 5 mm/s, and 5.1 mm/s reaches 0.05"),
])
def test_a_lowest_friction_no_finger_speed_reaches_with_a_margin_asks_for_a_higher_one(lowest_mu: float,
                                                                                       reach: str) -> None:
    """Below the speed floor (or within SPEED_MARGIN of it) a slower swipe cannot help: no speed is suggested, the
    texture's lowest friction is, one the drive reaches at the run's speed (rounded up)."""
    tally = FingerTally(touching=1000, saturated=500, speed_sum_mm_s=100_000.0, force_sum_n=500.0, lowest_mu=lowest_mu)
    why, _ = hint_lines(tally, Device.default(), 40.0, 0.8, judged=1000, departed=500, departed_saturated=400)
    assert (f"; {reach}: raise the texture's lowest friction to 0.64, or use a device with more headroom") in why, why
    assert "try --input" not in why


@pytest.mark.parametrize("speed_mm_s", [0.0, 8.0])
def test_a_finger_too_slow_to_halve_is_not_told_to_go_slower(speed_mm_s: float) -> None:
    """A still or tapping finger (0 mm/s), or one whose half speed is below the 5 mm/s floor, departs at the
    texture's changes: the hint asks for gentler changes, not a slower (or faster) swipe."""
    tally = FingerTally(touching=1000, saturated=0, speed_sum_mm_s=1000 * speed_mm_s, force_sum_n=500.0, lowest_mu=0.6)
    (line,) = hint_lines(tally, Device.default(), 40.0, 0.8, judged=1000, departed=100, departed_saturated=0)
    assert line.endswith("; gentler changes in the texture leave more headroom; --record then `tpad-rt plot` shows "
                         "where"), line
    assert "swipe" not in line


def test_a_finger_at_no_force_is_not_told_to_swipe_at_no_force() -> None:
    """A finger pressing 0 N: the swipe a hint suggests presses with the swipe's own force."""
    device = Device.default()
    for lowest_mu, saturated in ((0.6, 0), (0.3, 500)):
        tally = FingerTally(touching=1000, saturated=saturated, speed_sum_mm_s=60_000.0, force_sum_n=0.0,
                            lowest_mu=lowest_mu)
        line = hint_lines(tally, device, 40.0, 0.8, judged=1000, departed=100, departed_saturated=0)[0]
        suggested = line.split("try --input '")[1].split("'")[0]
        assert suggested.startswith("scripted://swipe?speed_mm_s=") and "force_n" not in suggested, line
