"""The offline render loop: an input drives a pipeline, block by block, into outputs.

Per block: push the input's finger samples up to the block's end time into the
pipeline, render the block, hand the drive and the block's telemetry row to every
output, keep the row (and the drive, if asked). A step does this for up to
STEP_BLOCKS blocks in one native call (:meth:`tpad_rt.pipeline.Pipeline.render_blocks`),
then hands the outputs every block at once (:meth:`tpad_rt.outputs.Output.write_blocks`):
no Python runs per block, and the samples are the same to the bit as block by block.
Only a step holding a finger sample the pipeline refuses goes block by block, to name
that sample. After ``input_s`` seconds of input the pipeline is stopped and rendered for
a tail long enough for its ramp to reach silence.
Nothing here waits for a clock: ``tpad-rt render`` runs it as fast as it goes
(``tpad-rt play`` uses the real-time :class:`tpad_rt.engine.Renderer` instead).

API map
-------
OfflineRender(pipeline, source, outputs, block_frames=, input_s=, tail_s=, force_n=, keep_drive=)
    ``.warm_up()``; ``.step()`` renders the next blocks (at most STEP_BLOCKS); ``.done``, ``.blocks_done``,
    ``.total_blocks``,
    ``.stop_early()``; ``.latest`` (the last block's telemetry row and output
    measurements); ``.result()`` -> RenderResult
RenderResult
    ``fs_hz``, ``block_frames``, ``drive`` (float32 or None), ``blocks`` (name -> array),
    ``finger`` (every finger sample pushed), ``seconds`` of audio rendered
texture_under_finger(result, texture) -> (mu, valid)
    the texture's friction where the finger really was at each block's middle
input_span_s(source, duration_s) -> float
    how long to follow the input; ConfigError for an endless input without a duration,
    or one longer than MAX_RENDER_S
check_render_size(input_s, tail_s, fs_hz, block_frames, keep_drive)
    ConfigError when a render would keep more than MAX_RENDER_BLOCKS telemetry rows or
    MAX_RECORDING_SAMPLES drive samples; call it before anything is allocated
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from tpad_rt.errors import ConfigError, SampleError
from tpad_rt.inputs import Input
from tpad_rt.felt import texture_at_finger
from tpad_rt.inputs.base import FINGER_DTYPE
from tpad_rt.kernel.layout import FINGER_COLS, FINGER_DOWN, FINGER_FORCE_N, FINGER_T_S, FINGER_X_MM, FINGER_Y_MM, TEL_NAMES
from tpad_rt.limits import MAX_RECORDING_SAMPLES, MAX_RENDER_BLOCKS, MAX_RENDER_S
from tpad_rt.outputs import Output
from tpad_rt.outputs.wav import BYTES_PER_SAMPLE as WAV_BYTES_PER_SAMPLE
from tpad_rt.outputs.wav import MAX_DATA_BYTES as WAV_MAX_DATA_BYTES
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import CompiledTexture


#: Blocks rendered per :meth:`OfflineRender.step` at most: fewer when the telemetry ring holds fewer, or
#: when they would hold more than STEP_SAMPLES samples (the step's drive buffer: 2 MiB).
STEP_BLOCKS = 8192
STEP_SAMPLES = 1 << 19


@dataclass(frozen=True)
class RenderResult:
    """What a render produced: per-block arrays (telemetry, then output measurements) and the drive."""

    fs_hz: int
    block_frames: int
    drive: npt.NDArray[np.float32] | None
    blocks: dict[str, np.ndarray]
    finger: np.ndarray
    #: :func:`texture_under_finger`'s answers, by the texture's id: (texture, mu, valid), read-only
    _felt: dict[int, tuple[CompiledTexture, np.ndarray, np.ndarray]] = field(
        default_factory=dict, init=False, repr=False, compare=False)

    @property
    def seconds(self) -> float:
        """Audio rendered (s)."""
        return len(self.blocks["t"]) * self.block_frames / self.fs_hz


def input_span_s(source: Input, duration_s: float | None) -> float:
    """``duration_s`` if given, else the input's natural duration (s).

    Raises ConfigError when the input is endless and no duration is given, or the
    duration is not a number in (0, MAX_RENDER_S].
    """
    span_s = source.duration_s if duration_s is None else duration_s
    if span_s is None:
        raise ConfigError("the input never ends (an endless pattern); give a duration (--duration SECONDS)")
    if not 0 < span_s <= MAX_RENDER_S:
        given = "ends after" if duration_s is None else "duration:"
        raise ConfigError(f"{given} {span_s:g} s, but a render must last more than 0 s and at most {MAX_RENDER_S:g} s; "
                          "render part of the input with --duration SECONDS")
    return span_s


def _blocks(seconds: float, fs_hz: float, block_frames: int) -> int:
    """Blocks of ``block_frames`` samples at ``fs_hz`` (Hz) that cover ``seconds`` (s, finite)."""
    return math.ceil(seconds * fs_hz / block_frames)


def check_render_size(input_s: float, tail_s: float, fs_hz: int, block_frames: int, keep_drive: bool,
                      writes_wav: bool = False) -> None:
    """Refuse a render too large to hold, before anything is allocated.

    An :class:`OfflineRender` of ``input_s`` + ``tail_s`` (s) at ``fs_hz`` (Hz) in
    blocks of ``block_frames`` keeps one telemetry row per block and, with
    ``keep_drive``, every drive sample; ``writes_wav``: it also writes them to a WAV
    file. Raises ConfigError when that is more than MAX_RENDER_BLOCKS rows,
    MAX_RECORDING_SAMPLES samples kept, or a WAV past its 4 GiB size limit.
    """
    blocks = _blocks(input_s, fs_hz, block_frames) + _blocks(tail_s, fs_hz, block_frames)
    if blocks > MAX_RENDER_BLOCKS:
        raise ConfigError(f"{input_s:g} s at {fs_hz} Hz in blocks of {block_frames} is {blocks:,} blocks, more than "
                          f"the {MAX_RENDER_BLOCKS:,} a render keeps telemetry for; render less (--duration) or in "
                          "longer blocks (--block)")
    if keep_drive and blocks * block_frames > MAX_RECORDING_SAMPLES:
        raise ConfigError(f"a recording of {input_s:g} s at {fs_hz} Hz holds {blocks * block_frames:,} drive samples, "
                          f"more than the {MAX_RECORDING_SAMPLES:,} a recording keeps in memory "
                          f"({MAX_RECORDING_SAMPLES // fs_hz} s at this rate); render less (--duration) or to .wav")
    wav_bytes = blocks * block_frames * WAV_BYTES_PER_SAMPLE
    if writes_wav and wav_bytes > WAV_MAX_DATA_BYTES:
        raise ConfigError(f"{input_s:g} s at {fs_hz} Hz is {wav_bytes:,} bytes of WAV samples, more than the "
                          f"{WAV_MAX_DATA_BYTES:,} a WAV file holds (4 GiB); render less (--duration)")


class OfflineRender:
    """Renders ``input_s`` (s, ``inf``: until :meth:`stop_early`) of ``source`` through ``pipeline``
    into ``outputs``, then a ``tail_s`` (s) tail.

    ``block_frames`` samples per block; ``force_n`` (N) replaces every finger sample's
    force when given; ``keep_drive`` keeps every drive sample for :meth:`result`. The
    pipeline is started on the first :meth:`step`.
    """

    def __init__(
        self,
        pipeline: Pipeline,
        source: Input,
        outputs: Sequence[Output],
        *,
        block_frames: int,
        input_s: float,
        tail_s: float,
        force_n: float | None = None,
        keep_drive: bool = False,
    ):
        self.pipeline = pipeline
        self.source = source
        self.outputs = list(outputs)
        self.block_frames = block_frames
        self.force_n = force_n
        fs_hz = pipeline.fs_hz
        self.input_blocks: float = _blocks(input_s, fs_hz, block_frames) if math.isfinite(input_s) else math.inf
        self.tail_blocks = _blocks(tail_s, fs_hz, block_frames)
        self.blocks_done = 0
        self._step_blocks = max(1, min(STEP_BLOCKS, pipeline.options.telemetry_ring, STEP_SAMPLES // block_frames))
        self._buffer = np.zeros(self._step_blocks * block_frames, dtype=np.float32)
        self._drive: list[np.ndarray] | None = [] if keep_drive else None
        # A kept drive of known length is rendered in place, not copied out of the buffer and joined at the end.
        self._whole = np.zeros(int(self.total_blocks) * block_frames, dtype=np.float32) \
            if keep_drive and math.isfinite(self.total_blocks) else None
        self._rows: dict[str, list[np.ndarray]] = {name: [] for name in TEL_NAMES}
        self._pushed_until_s = -math.inf
        self._finger: list[np.ndarray] = []
        self.latest: dict[str, float] = {}

    @property
    def total_blocks(self) -> float:
        """Blocks in the whole render (``inf`` while following an endless input)."""
        return self.input_blocks + self.tail_blocks

    @property
    def done(self) -> bool:
        """True once every block has been rendered."""
        return self.blocks_done >= self.total_blocks

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) what :meth:`step` runs: the pipeline's batch kernel and the
        outputs' (nothing is rendered or written)."""
        self.pipeline.warm_up(batch=True)
        for output in self.outputs:
            output.warm(batch=True)

    def stop_early(self) -> None:
        """Stop following the input now: the remaining blocks are only the ramp tail."""
        self.input_blocks = min(self.input_blocks, self.blocks_done)

    def step(self) -> None:
        """Render the next blocks (module docstring): at most STEP_BLOCKS, ending where the input ends;
        does nothing once :attr:`done`."""
        if self.done:
            return
        pipeline, frames = self.pipeline, self.block_frames
        if self.blocks_done == 0:
            pipeline.start()
        if self.blocks_done == self.input_blocks:
            pipeline.stop()
        limit = self.input_blocks if self.blocks_done < self.input_blocks else self.total_blocks
        count = int(min(self._step_blocks, limit - self.blocks_done))
        ends_s = (pipeline.sample_index + frames * np.arange(1, count + 1)) / pipeline.fs_hz
        samples = self.source.samples_between(self._pushed_until_s, float(ends_s[-1]))
        self._pushed_until_s = float(ends_s[-1])
        self._finger.append(samples)
        due = np.searchsorted(samples["t_s"], ends_s, side="right")  # samples due by each block's end
        drive = self._buffer[:count * frames] if self._whole is None else \
            self._whole[self.blocks_done * frames:(self.blocks_done + count) * frames]
        try:
            pipeline.render_blocks(drive, frames, self._finger_rows(samples), due)
        except SampleError:  # a sample push_finger refuses: block by block, to name it (a ConfigError)
            self._render_one_by_one(drive, samples, due)
        telemetry = pipeline.drain_telemetry()
        for output in self.outputs:
            output.write_blocks(drive, frames, telemetry)
        for name in TEL_NAMES:
            self._rows[name].append(telemetry[name])
        if self._drive is not None and self._whole is None:
            self._drive.append(drive.copy())
        self.latest = {name: float(column[-1]) for name, column in telemetry.items()}
        for output in self.outputs:
            self.latest.update(output.latest())
        self.blocks_done += count

    def _finger_rows(self, samples: np.ndarray) -> np.ndarray:
        """``samples`` (FINGER_DTYPE) as finger ring rows ``(t_s, x_mm, y_mm, force_n or NaN, down)``, the
        force replaced by ``force_n`` when given."""
        rows = np.empty((len(samples), FINGER_COLS))
        rows[:, FINGER_T_S] = samples["t_s"]
        rows[:, FINGER_X_MM] = samples["x_mm"]
        rows[:, FINGER_Y_MM] = samples["y_mm"]
        rows[:, FINGER_FORCE_N] = samples["force_n"] if self.force_n is None else self.force_n
        rows[:, FINGER_DOWN] = np.where(samples["down"], 1.0, 0.0)
        return rows

    def _render_one_by_one(self, drive: np.ndarray, samples: np.ndarray, due: np.ndarray) -> None:
        """Push and render block by block (Pipeline.push_finger, Pipeline.render) into ``drive``."""
        frames = self.block_frames
        for k in range(len(due)):
            self._push(samples[due[k - 1] if k else 0:due[k]])
            self.pipeline.render(drive[k * frames:(k + 1) * frames])

    def _push(self, samples: np.ndarray) -> None:
        """Push ``samples`` (FINGER_DTYPE; force NaN: unknown) into the pipeline; a sample the pipeline
        refuses is a ConfigError naming the input's time (inputs validate their samples: a bug otherwise)."""
        for sample in samples:
            force_n = float(sample["force_n"]) if self.force_n is None else self.force_n
            try:
                self.pipeline.push_finger(float(sample["t_s"]), float(sample["x_mm"]), float(sample["y_mm"]),
                                          force_n=None if math.isnan(force_n) else force_n, down=bool(sample["down"]))
            except SampleError as error:
                raise ConfigError(f"input sample at t = {float(sample['t_s']):g} s: {error}") from None

    def result(self) -> RenderResult:
        """The blocks rendered so far: telemetry, every output's measurements, and the drive if kept."""
        blocks = {name: np.concatenate(arrays) for name, arrays in self._rows.items()}
        for output in self.outputs:
            blocks.update(output.measurements())
        drive = None
        if self._whole is not None:
            drive = self._whole[:self.blocks_done * self.block_frames]
        elif self._drive is not None:
            drive = np.concatenate(self._drive) if self._drive else np.zeros(0, dtype=np.float32)
        finger = np.concatenate(self._finger) if self._finger else np.zeros(0, dtype=FINGER_DTYPE)
        return RenderResult(int(self.pipeline.fs_hz), self.block_frames, drive, blocks, finger)


def texture_under_finger(result: RenderResult, texture: CompiledTexture) -> tuple[np.ndarray, np.ndarray]:
    """The texture's relative friction where the finger was at each block's middle, and where that is known.

    :func:`tpad_rt.felt.texture_at_finger` at the blocks' middle times: ``valid`` is
    False where the finger was lifted or the render ran past the input's last sample.
    This is what the finger should have felt, free of the kernel's own extrapolation.
    Computed once per result and texture (``tpad-rt render`` asks three times); the arrays are read-only.
    """
    known = result._felt.get(id(texture))
    if known is None or known[0] is not texture:
        middle_s = result.blocks["t"] + 0.5 * result.block_frames / result.fs_hz
        mu, valid = texture_at_finger(result.finger, texture, middle_s)
        mu.flags.writeable = valid.flags.writeable = False
        known = result._felt[id(texture)] = (texture, mu, valid)
    return known[1], known[2]
