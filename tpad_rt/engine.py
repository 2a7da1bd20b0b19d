"""The real-time engine: :class:`Renderer`, the API for applications.

API map
-------
Renderer(device=None, output="audio://", *, texture=None, rate_hz=192000, block_frames=64,
         options=RenderOptions(), stall_timeout_s=0.5)
    context manager; ``start()``, ``stop()``, ``set_texture(texture_or_path)``,
    ``push_finger(x_mm, y_mm, force_n=None, t=None)``, ``lift()``, ``now_s()``,
    ``stats() -> dict``, ``telemetry() -> dict[str, ndarray]``, ``iter_telemetry(period_s)``,
    ``record(path, input_url="api")``,
    ``join(timeout_s=None)``, ``check()``, ``stream_time_s()``, ``recent_fingers()``,
    ``texture_t0_s()``, ``.texture``, ``.drive``, ``.callback_table``, ``.rate_hz``,
    ``.block_frames``, ``.running``, ``.driver`` (what runs the output: :mod:`tpad_rt.drivers`)

Example::

    import time

    from tpad_rt.engine import Renderer

    with Renderer(output="audio://?rate=192000&block=64", texture="textures/grating.yaml") as renderer:
        for x_mm in range(10, 60):              # an app's own finger samples
            renderer.push_finger(x_mm, 20.0)     # stamped "now" on the stream's clock
            time.sleep(0.01)
        renderer.lift()
        print(renderer.stats())
    # leaving the block ramps the drive to 0, closes the stream, and re-raises any
    # error the audio device or the engine's thread met

docs/realtime.md is the design. The Renderer is a front over parts with one job each:
the :class:`tpad_rt.pipeline.Pipeline` (the kernel's arrays, finger and texture
checks); a :class:`tpad_rt.realtime.CallbackTable` sharing them with the native render
callback ``tpad_rt.kernel.callback.render_callback``; the driver the output's scheme
declares (:mod:`tpad_rt.drivers`: PortAudio calls the callback for ``audio://``, the
GIL-free streamer for ``serial://``, a paced Python thread for ``sim://``, ``null://``,
``wav://``); a :class:`tpad_rt.telemetry.TelemetryLog` (telemetry, totals, recording);
and a watcher thread that drains telemetry and polls the driver for failures.
"""

from __future__ import annotations

import contextlib
import math
import numbers
import threading
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from tpad_rt.device import Device
from tpad_rt.drive import DriveSpec
from tpad_rt.drivers import Driver, open_driver
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import table_layout as tab
from tpad_rt.kernel.layout import (
    CFG_POWER_AVG_W, CFG_POWER_CAP_W, OP_PUSH_ONE, STATE_GATE, STATE_NEXT_INDEX, STATE_RAMP_START, TEX_PROG_COLS,
)
from tpad_rt.limits import FINGER_TIME_WINDOW_S, MAX_BLOCK_FRAMES, MAX_STALL_TIMEOUT_S
from tpad_rt.outputs import Consumes
from tpad_rt.pipeline import Pipeline, RenderOptions, shown
from tpad_rt.realtime import CallbackTable, monotonic_ns
from tpad_rt.recording import run_metadata
from tpad_rt.telemetry import TelemetryLog
from tpad_rt.texture import CompiledTexture, load_compiled

#: Seconds between two passes of the watcher thread (telemetry drain, driver poll).
WATCH_PERIOD_S = 0.02

#: Friction 1 everywhere: the drive stays silent (the texture before any is set).
NO_TEXTURE = CompiledTexture(np.array([[OP_PUSH_ONE] + [0] * (TEX_PROG_COLS - 1)]), np.zeros(0), np.zeros(0), 1,
                             "none", "no texture (friction 1 everywhere)")


def _compiled(texture: CompiledTexture | str | Path | None) -> tuple[CompiledTexture, str | None]:
    """``(compiled texture, its path or None)``; ConfigError for a bad texture file."""
    if texture is None:
        return NO_TEXTURE, None
    if isinstance(texture, CompiledTexture):
        return texture, None
    return load_compiled(texture), str(texture)


class Renderer:
    """Renders textures for one device in real time on ``output``.

    ``device`` (None: ``Device.default()``); ``output`` an output URL: ``audio://[device
    name or index]?rate=&block=&channel=`` (rate and block, when written, override
    ``rate_hz`` and ``block_frames``); ``serial://PORT?envelope_hz=&buffer_ms=&frame_ms=&baud=``
    (a serial amplifier, docs/amplifiers.md: the kernel renders the envelope at
    ``envelope_hz``, which replaces ``rate_hz``, in frames of ``frame_ms``, which replace
    ``block_frames``; a default ``options.control_interval`` is scaled to keep its
    control period); or ``sim://``, ``null://``, ``wav://...`` run by a paced thread; ``texture`` a compiled texture, a texture file, or None (silent until
    :meth:`set_texture`); ``rate_hz`` the sample rate (Hz), ``block_frames`` the frames
    per callback; ``options`` the render settings (power budget, ramps, watchdog...);
    ``stall_timeout_s`` how long (s) an audio stream may go without a callback before
    it counts as stalled (at least 4 blocks' time: tpad_rt.drivers.audio_callback.STALL_MIN_BLOCKS).

    Raises ConfigError for a bad URL, texture or option (``stall_timeout_s`` not in
    ``(0, MAX_STALL_TIMEOUT_S]``), or a carrier above 0.45 x the
    rate (naming the rate needed); BackendError (at :meth:`start`) when the audio
    device cannot run the stream, or the serial amplifier cannot be opened or refuses the
    handshake. Errors met later by the stream or the engine's
    thread are re-raised by :meth:`stop`, :meth:`check` and on leaving a ``with`` block.
    A lost audio device (a stream that stopped by itself, e.g. a JACK server that died)
    is a BackendError; so is a stalled one (a hung device or a stopped JACK server: no
    callback for ``stall_timeout_s``). Either stream is abandoned, not stopped or closed
    (docs/realtime.md), so :meth:`stop` returns promptly, and audio stays unusable in
    this process: restart it.

    Finger samples may come from several threads (:meth:`push_finger` and :meth:`lift` take a
    lock; the callback never does) and are validated at the call (SampleError);
    :meth:`set_texture` from one thread at a time. The kernel's fault guard keeps the drive
    finite and within the device's limits whatever reaches it (``stats()["faults"]``).
    """

    def __init__(self, device: Device | None = None, output: str = "audio://", *,
                 texture: CompiledTexture | str | Path | None = None, rate_hz: int = 192000,
                 block_frames: int = 64, options: RenderOptions = RenderOptions(), stall_timeout_s: float = 0.5):
        self.device = device if device is not None else Device.default()
        self.output_url = output
        if not (isinstance(stall_timeout_s, (int, float)) and not isinstance(stall_timeout_s, bool)
                and 0 < stall_timeout_s <= MAX_STALL_TIMEOUT_S):
            raise ConfigError(f"stall_timeout_s: must be a number of seconds in (0, {MAX_STALL_TIMEOUT_S:g}], "
                              f"got {stall_timeout_s!r}")
        self.stall_timeout_s = float(stall_timeout_s)
        self._driver = open_driver(output, device=self.device, rate_hz=rate_hz, block_frames=block_frames,
                                   options=options, stall_timeout_s=self.stall_timeout_s)
        block_frames = self._driver.block_frames
        if not (isinstance(block_frames, numbers.Integral) and 1 <= block_frames <= MAX_BLOCK_FRAMES):
            raise ConfigError(f"block_frames: must be a whole number in [1, {MAX_BLOCK_FRAMES}], got "
                              f"{shown(block_frames)}")
        self._driver.block_frames = int(block_frames)
        self.options: RenderOptions = self._driver.options
        compiled, texture_path = _compiled(texture)
        self._texture_path: str | None = texture_path
        self._pipeline: Pipeline = Pipeline(self.device, compiled, fs_hz=self._driver.rate_hz, options=self.options,
                                  envelope_output=self._driver.consumes is Consumes.ENVELOPE)
        self.rate_hz: int = self._driver.rate_hz
        self._log: TelemetryLog = TelemetryLog(self._pipeline, self.rate_hz)
        self._driver.log = self._log  # what the output measures per block goes to the log
        self._table: CallbackTable | None = None  # while running
        self._last_table: CallbackTable | None = None  # the last run's, for stats() after stop()
        self._watcher: threading.Thread | None = None
        self._halt: threading.Event = threading.Event()
        self._ended: threading.Event = threading.Event()  # set by stop() and by an error in the watcher
        self._error: BaseException | None = None
        self._reported: BaseException | None = None  # the driver's failure the watcher raised
        self._producer: threading.Lock = threading.Lock()  # orders push_finger/lift callers (the callback takes no lock)
        self._texture: CompiledTexture = compiled
        self._texture_sets: int = 0  # set_texture calls so far
        self._record_from_sets: int = 0  # that count when record() was called
        self._record_input_url: str = "api"  # what fed the fingers, as record() was told

    # --- lifecycle -----------------------------------------------------------------

    @property
    def driver(self) -> Driver:
        """What runs the render callback for this output (:mod:`tpad_rt.drivers`)."""
        return self._driver

    @property
    def block_frames(self) -> int:
        """Frames per callback (on ``serial://``, per envelope frame: set by the amplifier's INFO at start)."""
        return self._driver.block_frames

    @property
    def running(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return self._table is not None

    @property
    def callback_table(self) -> CallbackTable | None:
        """The arrays the callback shares in the current run (statistics, block records), None when stopped."""
        return self._table

    def stream_time_s(self) -> float:
        """The output's own clock (s; PortAudio's stream time on ``audio://``), NaN where there is none."""
        return self._driver.stream_time_s() if self._table is not None else math.nan

    def start(self) -> None:
        """Warm the callback up, open and start the output; the drive ramps up while a finger slides.

        Raises BackendError when the output cannot run (missing PortAudio, unknown device, a rate it
        does not accept; a serial port that does not open or an amplifier refusing the handshake),
        ConfigError for a ``serial://`` ``buffer_ms`` more than the amplifier holds, ConfigError or
        BackendError when a paced output cannot open, RuntimeError if running.
        """
        if self.running:
            raise RuntimeError("Renderer.start: already running")
        self._error = self._reported = None
        self._halt.clear()
        self._ended.clear()
        driver = self._driver
        driver.prepare()
        table = CallbackTable(self._pipeline.arrays, self._texture, channels=driver.channels, channel=driver.channel)
        table.slot_t0_s[0] = self.now_s()
        self._last_table = table
        try:
            with _warm_notice(driver):  # the first run in a fresh numba cache compiles the kernels here
                driver.warm(table.copy())
                driver.open(self._pipeline)
            self._pipeline.start()
            self._table = table
            driver.start(table)
        except BaseException:
            self._pipeline.stop()
            self._table = None
            try:
                driver.close(self.options.ramp_ms)
            except Exception:  # noqa: BLE001 - the error that stopped the start is the one to see
                pass
            raise
        self._watcher = threading.Thread(target=self._watch, args=(table,), name="tpad-rt watcher", daemon=True)
        self._watcher.start()

    def stop(self) -> None:
        """Ramp the drive down to 0, then stop and close the output; again: nothing.

        The driver waits (bounded, :meth:`tpad_rt.drivers.Driver.wait_silent`) until the
        kernel's gain has reached 0 and the block holding the ramp's end went to the
        output. A lost or stalled stream is abandoned instead (returns promptly: within
        ``stall_timeout_s`` plus a second of a stall). Re-raises an error the output or the engine's threads met, and
        writes the recording :meth:`record` asked for.
        """
        table = self._table
        if table is None:
            self.check()
            return
        self._pipeline.stop()
        silent_by = None  # the index by which the drive is silent, once the driver waited for it
        interrupted: BaseException | None = None
        try:
            silent_by = self._driver.wait_silent(table, self._ended)
        except BaseException as error:  # noqa: BLE001 - Ctrl-C, a driver's error: close all the same, re-raise below
            interrupted = error
        self._halt.set()
        if self._watcher is not None:
            self._watcher.join()
            self._watcher = None
        try:
            closing = self._driver.close(self.options.ramp_ms)
            self._log.drain(table)
            for failure in (closing, self._log.failure):
                if failure is not None and failure is not self._reported:  # the watcher's is reported once
                    self._error = self._error or failure
            if self._log.recording:
                one_texture = self._texture_sets == self._record_from_sets  # else no one texture to judge against
                self._log.write_recording(self._metadata(), self._texture if one_texture else None,
                                          float(table.slot_t0_s[table.active_slot]))
        except BaseException as error:  # noqa: BLE001 - re-raised by check() below
            self._error = self._error or error
        finally:
            self._table = None
            self._ended.set()  # whatever failed: join() and iter_telemetry() return
        if interrupted is not None:
            raise interrupted
        gain_open = table.arrays.state[STATE_GATE] or table.arrays.state[STATE_RAMP_START]
        if silent_by is not None and table.next_sample >= silent_by and gain_open:
            self._error = self._error or RuntimeError("Renderer.stop: the drive was not ramped to 0")
        self.check()

    def join(self, timeout_s: float | None = None) -> None:
        """Wait (at most ``timeout_s`` s; None: no limit) until another thread stops the renderer or an
        error ends the run; re-raise that error (pynput style). Call :meth:`stop` after it to close."""
        self._ended.wait(timeout_s)
        self.check()

    def check(self) -> None:
        """Re-raise (once) the error the output or the engine's threads met, if any."""
        error, self._error = self._error, None
        if error is not None:
            raise error

    def __enter__(self) -> Renderer:
        """Start (unless already running); leaving the block stops."""
        if not self.running:
            self.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if error is None:
            self.stop()
            return
        try:
            self.stop()
        except Exception:  # the caller's exception is the one to see  # noqa: BLE001
            pass

    def _watch(self, table: CallbackTable) -> None:
        """Until halted: drain telemetry (and the drive when recording) and poll the driver; an error either
        meets is kept for :meth:`check`, and the drive ramps down."""
        try:
            while not self._halt.wait(WATCH_PERIOD_S):
                self._log.drain(table)
                failure = self._log.failure or self._driver.poll(table)
                if failure is not None and not self._halt.is_set():
                    self._reported = failure
                    raise failure
        except BaseException as error:  # noqa: BLE001 - re-raised in the caller's thread
            self._error = self._error or error
            self._pipeline.stop()
            self._ended.set()

    # --- textures and fingers ------------------------------------------------------

    def set_texture(self, texture: CompiledTexture | str | Path) -> None:
        """Render ``texture`` (compiled, or a file) from the next callback on; temporal textures start now.

        Atomic (the callback renders one texture or the other, never a mix) and
        phase-continuous (the carrier follows the sample index). Raises ConfigError
        for a bad texture file.
        """
        compiled, path = _compiled(texture)
        self._texture, self._texture_path = compiled, path
        self._texture_sets += 1
        if self._table is not None:
            self._table.set_texture(compiled, self.now_s(), running=True)
        else:
            self._pipeline.set_texture(compiled)

    @property
    def drive(self) -> DriveSpec:
        """The drive the run renders for (carrier, full scale, clamp, rate): the device file's, and from
        :meth:`start` on what the output's hardware reported (a serial amplifier's INFO and carrier)."""
        return self._pipeline.drive

    @property
    def texture(self) -> CompiledTexture:
        """The texture rendered (the last one set)."""
        return self._texture

    def texture_t0_s(self) -> float:
        """The stream time (s) at which the rendered texture started (its time origin; 0.0 before a run)."""
        table = self._last_table
        return float(table.slot_t0_s[table.active_slot]) if table is not None else 0.0

    def recent_fingers(self) -> np.ndarray:
        """The newest finger samples pushed (at most ``finger_ring - 2``), oldest first, as FINGER_DTYPE.

        Read without a lock while a producer may push: the ring's oldest row is left out.
        """
        return self._pipeline.recent_fingers()

    def now_s(self) -> float:
        """The stream time (s) of the sample at the DAC now (0.0 before the stream runs)."""
        if self._table is None:
            return float(self._pipeline.arrays.state[STATE_NEXT_INDEX]) / self.rate_hz
        return self._table.dac_sample(monotonic_ns()) / self.rate_hz

    def push_finger(self, x_mm: float, y_mm: float, force_n: float | None = None, t: float | None = None) -> None:
        """A finger sample at plate position ``(x_mm, y_mm)`` (mm), contact force ``force_n`` (N; None: the
        default), stream time ``t`` (s; None: now). Times are kept non-decreasing (an earlier one is
        raised to the previous). Safe from several threads (a lock orders the producers; the audio
        callback reads without one); no allocation.

        Raises SampleError (a ValueError) naming the argument, its range and the value for a value
        that is not a finite number, a position beyond one plate length (width) past the plate's
        edges, a force outside ``[0, tpad_rt.limits.MAX_FORCE_N]``, or a time further than
        ``tpad_rt.limits.FINGER_TIME_WINDOW_S`` from the stream clock; nothing is pushed then.
        """
        self._push((x_mm, y_mm), force_n, t, down=True)

    def lift(self, t: float | None = None) -> None:
        """The finger leaves the plate at stream time ``t`` (s; None: now): the drive ramps to 0.
        Raises SampleError for a bad ``t`` (as :meth:`push_finger`)."""
        self._push(None, None, t, down=False)

    def _push(self, position_mm: tuple[float, float] | None, force_n: float | None, t: float | None,
              down: bool) -> None:
        """Push a sample at ``position_mm`` (None: where the last one was) at ``t`` (None: now, kept within
        the pipeline's window around its stream position, which a stalled stream stops advancing)."""
        with self._producer:
            if t is None:
                stream_s = self._pipeline.stream_time_s
                t_s = min(max(self.now_s(), stream_s - FINGER_TIME_WINDOW_S), stream_s + FINGER_TIME_WINDOW_S)
            else:
                t_s = self._pipeline.check_time(t, "t")
            t_s = max(t_s, self._pipeline.last_time_s)
            x_mm, y_mm = self._pipeline.last_position_mm() if position_mm is None else position_mm
            pushed_ns = monotonic_ns()
            index = int(self._pipeline.arrays.finger_count[0])
            self._pipeline.push_finger(t_s, x_mm, y_mm, force_n, down)
            self._log.note_push(index, pushed_ns)

    # --- measurements --------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        """Counters and distributions so far (units in the keys; NaN where nothing was measured yet).

        ``callbacks``, ``frames``, ``underflows`` (of the current or last run), ``rate_hz``,
        ``block_frames``, ``played_s`` (seconds of drive the output took: ``frames / rate_hz``);
        ``compute_us_p50/p99/max``
        (time in the callback, over the recent blocks); ``callback_load_p99`` (that p99 as a
        fraction of a block's duration); ``blocks``,
        ``voltage_saturated``, ``power_saturated``, ``fault_blocks`` (blocks), ``voltage_peak_v`` (the drive's
        peak, V), ``kick_blocks`` (blocks in which the shaper held the drive at a limit to move the plate as fast as
        it allows: telemetry flag SHAPER_LIMIT, by design, not saturation) and ``voltage_peak_outside_kicks_v``
        (the peak in the other blocks, V), ``power_mean_w``,
        ``power_peak_w``, ``power_budget_w``, ``power_avg_w`` (from telemetry); ``plate_peak_w`` (the most power
        the plate held, as the kernel's model has it) and ``over_cap_blocks`` (blocks in which that was over the cap:
        a press);
        ``latency_ms_p50/p99``: from a push to the DAC time of the first block that
        read it, over every block since the renderer was made (a running histogram: within 1.2 %,
        tpad_rt.telemetry); ``dac_delay_ms``: the part of it the host
        reports from a callback to the DAC (median over the recent blocks, from the
        time stamps PortAudio passes each callback; 0 on paced outputs; PortAudio's
        stream-level ``outputLatency`` is not reported: JACK's dummy driver says 0 there
        while its callbacks' time stamps say 0.33 ms); ``lead_bound_ms``, the most of that delay the output can
        have (CallbackTable.set_lead_bound_s), and ``lead_over_blocks``, blocks whose reported delay was above it
        or not a number (taken as the bound); ``faults``, ``fault_steps``, ``fault_samples``, ``fault_causes``: the kernel's fault
        guard (docs/kernel.md "Faults"), since the renderer was made.
        """
        if self._table is not None:
            self._log.drain(self._table)
        table = self._last_table
        result: dict[str, Any] = {"rate_hz": self.rate_hz, "block_frames": self.block_frames}
        if table is not None:
            counters = table.stats.copy()
            blocks = table.recent_blocks()
        else:
            counters, blocks = np.zeros(tab.STAT_SIZE, dtype=np.int64), np.zeros((0, tab.BLOCK_COLS), dtype=np.int64)
        result.update(callbacks=int(counters[tab.STAT_CALLBACKS]), frames=int(counters[tab.STAT_FRAMES]),
                      underflows=int(counters[tab.STAT_UNDERFLOWS]), lead_over_blocks=int(counters[tab.STAT_LEAD_OVER]),
                      lead_bound_ms=table.lead_bound_s * 1e3 if table is not None else 0.0,
                      played_s=int(counters[tab.STAT_FRAMES]) / self.rate_hz)
        result.update(self._driver.stats())
        compute_us = blocks[:, tab.BLOCK_COMPUTE_NS] * 1e-3
        for name, q in (("p50", 50), ("p99", 99), ("max", 100)):
            result[f"compute_us_{name}"] = float(np.percentile(compute_us, q)) if len(compute_us) else math.nan
        result["callback_load_p99"] = result["compute_us_p99"] * 1e-6 * self.rate_hz / self.block_frames
        dac_delay_ms = blocks[:, tab.BLOCK_DAC_DELAY_NS] * 1e-6
        result["dac_delay_ms"] = float(np.median(dac_delay_ms)) if len(dac_delay_ms) else math.nan
        result.update(self._log.latency_ms())
        totals = self._log.totals()
        cfg = self._pipeline.arrays.cfg
        result.update(blocks=totals["blocks"], voltage_saturated=totals["voltage_saturated"],
                      power_saturated=totals["power_saturated"], fault_blocks=totals["fault_blocks"],
                      power_mean_w=totals["energy_w"] / totals["blocks"] if totals["blocks"] else math.nan,
                      power_peak_w=totals["peak_w"], power_budget_w=float(cfg[CFG_POWER_CAP_W]),
                      power_avg_w=float(cfg[CFG_POWER_AVG_W]), plate_peak_w=totals["plate_peak_w"],
                      voltage_peak_v=totals["peak_v"], kick_blocks=totals["kick_blocks"],
                      voltage_peak_outside_kicks_v=totals["peak_outside_kicks_v"],
                      over_cap_blocks=self._pipeline.over_cap_blocks)
        result.update(self._pipeline.faults())
        return result

    def telemetry(self) -> dict[str, np.ndarray]:
        """The telemetry rows since the last call (at most tpad_rt.telemetry.MAX_PENDING_ROWS, the newest), by TEL_NAMES
        column, and by the columns the output measured per block (``sim://``: ``plate_amplitude_um``,
        ``achieved_mu``; NaN for a block it did not measure)."""
        if self._table is not None:
            self._log.drain(self._table)
        return self._log.take()

    def iter_telemetry(self, period_s: float = 0.05) -> Iterator[dict[str, np.ndarray]]:
        """Yield the new telemetry rows (as :meth:`telemetry` gives them) every ``period_s`` (s) while the
        renderer runs, skipping empty periods; the last rows after it stops, then end (re-raising an
        error the run met). One consumer at a time: :meth:`telemetry` takes the same rows. Raises
        RuntimeError unless running when iteration starts."""
        if not self.running:
            raise RuntimeError("Renderer.iter_telemetry: not running (start() first)")
        while not self._ended.wait(period_s):
            rows = self.telemetry()
            if len(rows["t"]):
                yield rows
        rows = self.telemetry()
        if len(rows["t"]):
            yield rows
        self.check()

    def record(self, path: str | Path, input_url: str = "api") -> None:
        """Record the drive and telemetry from now on; :meth:`stop` writes them to ``path`` (.npz, the
        format of ``tpad-rt render``), its metadata naming ``input_url`` as what fed the fingers (``"api"``:
        the caller's own pushes). On an output that measures the plate (``sim://``) the recording has the
        simulated plate's columns, and, when one texture was rendered all along, ``departed``
        (tpad_rt.telemetry). Raises ConfigError unless ``path`` ends in ``.npz``, or when it is no
        place to write (no folder, a FIFO, a directory). A recording
        keeps at most ``tpad_rt.limits.MAX_RECORDING_SAMPLES`` drive samples in memory: past that the
        run ends with a TpadError (re-raised once, by :meth:`check`, :meth:`join` or :meth:`stop`), and
        :meth:`stop` writes what came before it, its metadata's ``truncated`` saying why."""
        self._log.record(path)
        self._record_from_sets = self._texture_sets
        self._record_input_url = input_url

    def _metadata(self) -> dict[str, Any]:
        """The recording's metadata (:func:`tpad_rt.recording.run_metadata`)."""
        return run_metadata(self._pipeline, self._texture, texture_path=self._texture_path,
                            block_frames=self.block_frames, input_url=self._record_input_url,
                            output_url=self.output_url)


def _warm_notice(driver: Driver) -> contextlib.AbstractContextManager[object]:
    """The compile notice (:func:`tpad_rt.compiling.compile_notice`) around warming ``driver`` up and opening it,
    after compiling the whole compile plan when numba's cache lacks it (:func:`tpad_rt.compiling.ensure_compiled`),
    unless the driver compiles nothing (its callback and output are ahead-of-time code): numba is then not
    imported."""
    if not driver.warm_compiles():
        return contextlib.nullcontext()
    from tpad_rt.compiling import compile_notice, ensure_compiled

    ensure_compiled()  # every kernel of every path, in worker processes, when numba's cache lacks them
    return compile_notice()
