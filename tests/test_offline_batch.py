"""The offline render's native batch (Pipeline.render_blocks, SimOutput.write_blocks) against a naive reference:
finger samples pushed one by one with Pipeline.push_finger, one Pipeline.render per block, and the simulated
plate advanced block by block by SimOutput.write (the real-time path: the sim kernel's resonate and the
friction model's core, one block at a time). Every sample, telemetry column and plate measurement must be the
same to the bit."""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np
import pytest

from tpad_rt.device import Device
from tpad_rt.errors import ConfigError, SampleError
from tpad_rt.inputs import open_input
from tpad_rt.kernel import layout
from tpad_rt.offline import OfflineRender, RenderResult
from tpad_rt.outputs.sim import SimOutput
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

TEXTURES = Path(__file__).resolve().parents[1] / "textures"
RATE_HZ = 192000
TAIL_S = 0.01
#: Input seconds are scaled by this: the kernel coverage run (tests/run) runs the kernels as Python.
SCALE = 1.0 if not numba.config.DISABLE_JIT else 0.1


def _blocks(seconds: float, block: int) -> int:
    return math.ceil(seconds * RATE_HZ / block)


def _batched(texture: str, url: str, block: int, input_s: float, force_n: float | None) -> RenderResult:
    device = Device.default()
    pipeline = Pipeline(device, load_compiled(TEXTURES / texture), fs_hz=RATE_HZ)
    with open_input(url) as source:
        render = OfflineRender(pipeline, source, [SimOutput(device, RATE_HZ)], block_frames=block, input_s=input_s,
                               tail_s=TAIL_S, force_n=force_n, keep_drive=True)
        while not render.done:
            render.step()
    return render.result()


def _reference(texture: str, url: str, block: int, input_s: float, force_n: float | None
               ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The drive and every per-block column, from Python block by block."""
    device = Device.default()
    pipeline = Pipeline(device, load_compiled(TEXTURES / texture), fs_hz=RATE_HZ)
    input_blocks = _blocks(input_s, block)
    plate = SimOutput(device, RATE_HZ)
    drive, rows = [], []
    pushed_until_s = -math.inf
    pipeline.start()
    with open_input(url) as source:
        for k in range(input_blocks + _blocks(TAIL_S, block)):
            if k == input_blocks:
                pipeline.stop()
            end_s = (pipeline.sample_index + block) / RATE_HZ
            for sample in source.samples_between(pushed_until_s, end_s):
                force = float(sample["force_n"]) if force_n is None else force_n
                pipeline.push_finger(float(sample["t_s"]), float(sample["x_mm"]), float(sample["y_mm"]),
                                     force_n=None if math.isnan(force) else force, down=bool(sample["down"]))
            pushed_until_s = end_s
            out = np.zeros(block, dtype=np.float32)
            pipeline.render(out)
            row = pipeline.last_telemetry_row()
            plate.write(out, row)
            drive.append(out)
            rows.append(row)
    columns = {name: np.array([row[name] for row in rows]) for name in layout.TEL_NAMES}
    return np.concatenate(drive), {**columns, **plate.measurements()}


@pytest.mark.parametrize(("texture", "url", "block", "input_s", "force_n"), [
    ("grating.yaml", "scripted://swipe?speed_mm_s=100&back_and_forth=1&repeat=0", 64, 0.6, None),
    ("bumps_grid.yaml", "scripted://circle?speed_mm_s=150", 257, 0.3, None),
    ("layers_modulated.yaml", "scripted://tap?down_s=0.02&up_s=0.02&count=0", 16, 0.5, None),  # lifts and touches again
    ("gradient_bump.yaml", "scripted://swipe?speed_mm_s=60", 100, 0.3, 1.2),  # the force replaced
])
def test_the_batch_renders_what_pushing_and_rendering_block_by_block_renders(
        texture: str, url: str, block: int, input_s: float, force_n: float | None) -> None:
    input_s *= SCALE
    batched = _batched(texture, url, block, input_s, force_n)
    drive, columns = _reference(texture, url, block, input_s, force_n)
    assert batched.drive is not None and np.array_equal(batched.drive, drive)
    assert set(batched.blocks) == set(columns)
    for name, column in columns.items():
        assert np.array_equal(batched.blocks[name], column, equal_nan=True), name
    assert np.abs(drive).max() > 0.1  # something was rendered
    if "tap" in url:
        assert set(batched.finger["down"].tolist()) == {False, True}  # lifted and touching within the render


def test_render_blocks_refuses_a_sample_push_finger_refuses() -> None:
    device = Device.default()
    pipeline = Pipeline(device, load_compiled(TEXTURES / "grating.yaml"), fs_hz=RATE_HZ)
    rows = np.array([[0.0, 10.0, 10.0, math.nan, 1.0], [0.0001, 1e9, 10.0, math.nan, 1.0]])
    due = np.array([1, 2])
    assert not pipeline.finger_rows_pass(rows, due, 64)
    with pytest.raises(SampleError, match="push them one by one"):
        pipeline.render_blocks(np.zeros(128, dtype=np.float32), 64, rows, due)
    assert pipeline.sample_index == 0  # nothing rendered
    good = rows.copy()
    good[1, 1] = 20.0
    assert pipeline.finger_rows_pass(good, due, 64)
    backwards = good[::-1].copy()
    assert not pipeline.finger_rows_pass(backwards, due, 64)  # times must not decrease


class _Backwards:
    """An input whose third sample of each read goes back in time (no shipped input does that)."""

    def __init__(self, source: object) -> None:
        self._source = source

    def samples_between(self, begin_s: float, end_s: float) -> np.ndarray:
        samples = self._source.samples_between(begin_s, end_s).copy()  # type: ignore[attr-defined]
        if len(samples) > 3:
            samples["t_s"][2] = samples["t_s"][0] - 0.001
        return samples


def test_an_input_sample_the_pipeline_refuses_is_named_by_its_time() -> None:
    """The batch goes block by block when a sample is refused, so the error names that sample as before."""
    device = Device.default()
    pipeline = Pipeline(device, load_compiled(TEXTURES / "grating.yaml"), fs_hz=RATE_HZ)
    with open_input("scripted://swipe?speed_mm_s=100") as source:
        render = OfflineRender(pipeline, _Backwards(source), [SimOutput(device, RATE_HZ)],  # type: ignore[arg-type]
                               block_frames=64, input_s=0.2, tail_s=TAIL_S)
        with pytest.raises(ConfigError, match=r"input sample at t = -0.001 s: t_s: must be >= the previous sample"):
            while not render.done:
                render.step()


def test_the_batch_kernel_stays_within_its_arrays_whatever_due_holds() -> None:
    """Called directly (Pipeline.render_blocks checks first), the kernel pushes no row past ``rows`` and renders no
    block past ``out``."""
    from tpad_rt.kernel.batch import render_blocks

    pipeline = Pipeline(Device.default(), load_compiled(TEXTURES / "grating.yaml"), fs_hz=RATE_HZ)
    out = np.full(100, 7.0, dtype=np.float32)
    rows = np.array([[0.0, 10.0, 10.0, math.nan, 1.0]])
    render_blocks(out, 64, 0, rows, np.array([5, 1000, 10**9], dtype=np.int64), *pipeline.arrays)
    assert int(pipeline.arrays.finger_count[0]) == 1  # one row, not five
    assert np.all(np.isfinite(out[:64])) and np.all(out[64:] == 7.0)  # one whole block fits; nothing after it


def test_a_force_that_varies_from_sample_to_sample_renders_the_same(tmp_path: Path) -> None:
    """Many contact forces within one step: the plate's coefficients change from block to block."""
    t_s = np.arange(0.0, 0.3 * SCALE + 0.01, 0.001)
    x_mm = 20.0 + 100.0 * t_s
    force_n = 0.3 + 0.25 * np.sin(2 * np.pi * 7.0 * t_s) + 0.001 * np.arange(len(t_s)) % 0.05
    trajectory = tmp_path / "t.csv"
    trajectory.write_text("t,x_mm,y_mm,force_n\n" + "".join(
        f"{t:.6f},{x:.6f},30,{f:.6f}\n" for t, x, f in zip(t_s, x_mm, force_n)))
    url = f"file://{trajectory}"
    batched = _batched("grating.yaml", url, 64, 0.3 * SCALE, None)
    drive, columns = _reference("grating.yaml", url, 64, 0.3 * SCALE, None)
    assert len(np.unique(columns["force_n"])) > 10
    assert batched.drive is not None and np.array_equal(batched.drive, drive)
    for name, column in columns.items():
        assert np.array_equal(batched.blocks[name], column, equal_nan=True), name
