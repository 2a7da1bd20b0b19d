"""The texture under the finger (tpad_rt.felt), and the finger samples a Renderer holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpad_rt.engine import Renderer
from tpad_rt.felt import start_ramps, texture_at_finger
from tpad_rt.inputs.base import FINGER_DTYPE
from tpad_rt.texture import load_compiled

TEXTURES = Path(__file__).resolve().parents[1] / "textures"


def _fingers(*rows: tuple[float, float, float, bool]) -> np.ndarray:
    samples = np.zeros(len(rows), dtype=FINGER_DTYPE)
    for i, (t_s, x_mm, y_mm, down) in enumerate(rows):
        samples[i] = (t_s, x_mm, y_mm, np.nan, down)
    return samples


def test_the_position_is_interpolated_between_samples_and_moves_the_friction() -> None:
    texture = load_compiled(TEXTURES / "grating.yaml")
    fingers = _fingers((0.0, 10.0, 20.0, True), (1.0, 20.0, 20.0, True))
    times = np.array([0.25, 0.5, 0.75])
    mu, valid = texture_at_finger(fingers, texture, times)
    assert valid.all()
    np.testing.assert_allclose(mu, texture.evaluate([12.5, 15.0, 17.5], 20.0, 1.0, 0.0, times))
    assert np.ptp(texture.evaluate(np.linspace(10, 20, 101), 20.0)) > 0.1  # the grating varies along x


def test_outside_the_samples_or_lifted_is_not_known() -> None:
    texture = load_compiled(TEXTURES / "grating.yaml")
    fingers = _fingers((1.0, 10.0, 20.0, True), (2.0, 12.0, 20.0, True), (3.0, 12.0, 20.0, False),
                       (4.0, 14.0, 20.0, True))
    mu, valid = texture_at_finger(fingers, texture, np.array([0.5, 1.5, 2.5, 3.5, 4.5]))
    assert valid.tolist() == [False, True, False, False, False]
    assert mu[~valid].tolist() == [1.0] * 4


def test_a_temporal_texture_is_read_at_its_own_time() -> None:
    texture = load_compiled(TEXTURES / "temporal_pulse.yaml")  # 30 Hz: 1.0 for the first 30 % of a cycle, then 0.6
    fingers = _fingers((10.0, 30.0, 20.0, True), (11.0, 40.0, 20.0, True))
    times = np.array([10.0 + 1e-4, 10.0 + 0.6 / 30])
    mu, valid = texture_at_finger(fingers, texture, times, texture_t0_s=10.0 - 0.5 / 30)  # half a cycle in at 10 s
    assert valid.all()
    assert mu.tolist() == [0.6, 1.0]
    assert texture_at_finger(fingers, texture, times)[0].tolist() == [1.0, 0.6]  # from t0 = 0: 300 cycles in


def _naive_start_ramps(t_s: np.ndarray, touching: np.ndarray, window_s: float) -> np.ndarray:
    ramping, start_s, before = np.zeros(len(t_s), dtype=bool), -np.inf, False
    for k, (t, now) in enumerate(zip(t_s, touching)):
        if now and not before:
            start_s = t
        ramping[k] = bool(now) and t - start_s < window_s
        before = bool(now)
    return ramping


def test_start_ramps_match_a_loop_whole_and_in_chunks() -> None:
    rng = np.random.default_rng(7)
    t_s = np.arange(2000) / 3000.0
    touching = np.repeat(rng.random(40) < 0.7, 50)  # touches of 50-block runs, some back to back
    touching[:3] = True  # a run touching from the first block starts a touch there
    window_s = 0.004
    expected = _naive_start_ramps(t_s, touching, window_s)
    whole, _ = start_ramps(t_s, touching, window_s)
    np.testing.assert_array_equal(whole, expected)
    assert 0 < expected.sum() < touching.sum()
    chunks, start_s, before = [], -np.inf, False
    for cut in np.array_split(np.arange(len(t_s)), 37):  # chunks that split touches and ramps
        part, start_s = start_ramps(t_s[cut], touching[cut], window_s, start_s, before)
        before = bool(touching[cut][-1])
        chunks.append(part)
    np.testing.assert_array_equal(np.concatenate(chunks), expected)


def test_the_renderer_keeps_its_newest_finger_samples_in_order() -> None:
    renderer = Renderer(output="null://", texture=TEXTURES / "grating.yaml")
    ring = renderer.options.finger_ring
    for k in range(ring + 10):
        renderer.push_finger(k * 0.1, 20.0, 0.5, t=k * 0.001)  # x_mm numbers the samples
    renderer.lift(t=(ring + 10) * 0.001)
    fingers = renderer.recent_fingers()
    assert len(fingers) == ring - 2
    assert np.all(np.diff(fingers["t_s"]) > 0)
    assert fingers["x_mm"][-2] == (ring + 9) * 0.1 and fingers["down"][-2] and not fingers["down"][-1]
    assert fingers["x_mm"][-1] == (ring + 9) * 0.1  # a lift keeps the last position
    assert np.all(fingers["force_n"][:-1] == 0.5)
