"""The ``audio://`` driver: PortAudio's audio thread calls the native render callback.

The callback is the render callback (:func:`tpad_rt.aot.library.render_callback`: the ahead-of-time
library's when it is built, else ``tpad_rt.kernel.callback.render_callback``), handed to PortAudio with
the table's address as ``userData`` (:class:`tpad_rt.outputs.audio.AudioStream`): no
Python runs per block (docs/realtime.md says why). A stream that stops by itself (its
device or JACK server went away) or stops calling back for the stall limit is
abandoned, not stopped or closed: PortAudio's JACK host API hangs or aborts then.
"""

from __future__ import annotations

import math
import threading
from typing import Any

from tpad_rt.clock import Clock
from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.drivers.stall_watch import StallWatch
from tpad_rt.errors import BackendError
from tpad_rt.aot import library as native
from tpad_rt.kernel import table_layout as tab
from tpad_rt.kernel.layout import MAX_OUTPUT_LEAD_S
from tpad_rt.outputs import audio
from tpad_rt.pipeline import RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.urls import Url

#: A stream counts as stalled after no fewer blocks' time than this without a callback (large blocks).
STALL_MIN_BLOCKS = 4
#: Stopping and closing a stream may take the stall limit plus this long (s; it takes tens of ms) before the
#: stream counts as stalled and is abandoned.
CLOSE_GRACE_S = 1.0


class AudioCallbackDriver(Driver):
    """An ``audio://`` output; its URL's ``rate`` and ``block``, when written, replace the renderer's.
    ``stall_timeout_s``: how long (s) the stream may go without a callback before it counts as stalled
    (at least STALL_MIN_BLOCKS blocks' time)."""

    def __init__(self, url: Url, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                 stall_timeout_s: float = 0.5, clock: Clock | None = None):
        target = audio.parse_audio_url(url)
        super().__init__(url, device=device, options=options, stall_timeout_s=stall_timeout_s, clock=clock,
                         rate_hz=target.rate_hz if "rate" in target.given else rate_hz,
                         block_frames=target.block_frames if "block" in target.given else block_frames)
        self.target = target
        self.audio_device: audio.AudioDevice | None = None  # found by prepare()
        self.stream: audio.AudioStream | None = None  # while started
        self._stalled = False
        self._failure: BackendError | None = None  # what poll() found, returned again by close()
        self._watch: StallWatch | None = None  # made by start()

    def stall_limit_s(self) -> float:
        """Seconds without a callback after which the stream counts as stalled."""
        return max(self.stall_timeout_s, STALL_MIN_BLOCKS * self.block_frames / self.rate_hz)

    def summary_lines(self, stats: dict[str, Any]) -> list[str]:
        """On a JACK server that buffers more than one period before the DAC (its asynchronous mode), how to
        take that period off the latency."""
        period_ms = 1e3 * stats["block_frames"] / stats["rate_hz"]
        device = self.audio_device
        if device is None or "JACK" not in device.host_api or not stats["dac_delay_ms"] > 1.5 * period_ms:
            return []
        return [f"the JACK server buffers {stats['dac_delay_ms'] / period_ms:.0f} periods before the DAC: "
                f"started with jackd -S (synchronous mode) it buffers one, {period_ms:.2f} ms less"]

    def warm_compiles(self) -> bool:
        """Only without the ahead-of-time library: PortAudio runs the callback and nothing else compiled."""
        return native.load() is None

    def prepare(self) -> None:
        """Find the device; BackendError when it is missing or lacks the URL's channel."""
        device = audio.find_output_device(self.target.device)
        if self.target.channel > device.channels:
            raise BackendError(f"audio: channel {self.target.channel}: device {device} has "
                               f"{device.channels} output channel(s)")
        self.audio_device = device
        self.channels, self.channel = device.channels, self.target.channel - 1

    def start(self, table: CallbackTable) -> None:
        """Open the stream on the native callback and start it; BackendError when the device refuses."""
        assert self.audio_device is not None, "prepare() first"
        self._stalled = False
        self._failure = None
        self._watch = StallWatch(round(self.stall_limit_s() * 1e9), self.clock)
        address = native.render_callback().address
        assert address is not None
        self.stream = audio.AudioStream(self.audio_device, self.rate_hz, self.block_frames, self.channels,
                                        address, table.user_data)
        table.set_lead_bound_s(lead_bound_s(self.stream.output_latency_s, self.block_frames, self.rate_hz))
        self.stream.start()

    def poll(self, table: CallbackTable) -> BaseException | None:
        """A BackendError when the stream stopped by itself, or made no callback for the stall limit (a
        :class:`StallWatch` on the driver's clock: the gap measured never exceeds the time without a callback,
        however late the watcher runs)."""
        stream, watch = self.stream, self._watch
        if stream is None or watch is None or self._failure is not None:
            return self._failure
        if not stream.active():
            self._failure = _lost_error(stream.device)
            return self._failure
        still_ns = watch.still_for_ns(lambda: int(table.stats[tab.STAT_CALLBACKS]))
        if still_ns is not None:
            self._stalled = True
            self._failure = _stall_error(stream.device, f"no callback for {still_ns * 1e-9:.2f} s")
        return self._failure

    def close(self, ramp_ms: float) -> BaseException | None:
        """Stop and close the stream; abandon it instead if it stalled or its device or server went away (and
        return the error that said so: the one :meth:`poll` returned, the same object).

        The stop and close run in a helper thread (PortAudio's JACK host API blocks in them for minutes
        when the server stops answering): if they take longer than the stall limit plus CLOSE_GRACE_S,
        the stream is abandoned and a BackendError (stalled) returned; so is a stop or close failing.
        """
        stream, self.stream = self.stream, None
        if stream is None:
            return self._failure
        if self._stalled or stream.lost():
            stream.abandon()
            return self._failure or _lost_error(stream.device)
        errors: list[BaseException] = []

        def shut() -> None:
            try:
                try:
                    stream.stop()
                finally:
                    stream.close()
            except BaseException as error:  # noqa: BLE001 - returned by the waiting thread
                errors.append(error)

        closer = threading.Thread(target=shut, name="tpad-rt stream close", daemon=True)
        closer.start()
        bound_s = self.stall_limit_s() + CLOSE_GRACE_S
        closer.join(bound_s)
        if closer.is_alive():
            stream.abandon()
            return _stall_error(stream.device, f"stopping it took over {bound_s:.2f} s")
        return errors[0] if errors else None

    def stream_time_s(self) -> float:
        """PortAudio's stream time (s), NaN when no stream runs."""
        stream = self.stream
        return stream.time_s() if stream is not None else math.nan


def lead_bound_s(output_latency_s: float, block_frames: int, rate_hz: int) -> float:
    """The most lead (s) a stream can have: the output latency PortAudio reported when it opened (NaN or
    negative: none) plus a block (a JACK server in asynchronous mode buffers a period more than it reports), at
    most MAX_OUTPUT_LEAD_S. A
    callback's time info saying more is taken as this much (CallbackTable.set_lead_bound_s)."""
    latency_s = output_latency_s if output_latency_s >= 0.0 else 0.0
    return min(latency_s + block_frames / rate_hz, MAX_OUTPUT_LEAD_S)


def _lost_error(device: audio.AudioDevice) -> BackendError:
    """The error of a stream on ``device`` that stopped by itself."""
    return BackendError(f"audio: the stream on device {device} stopped (device lost or server gone)")


def _stall_error(device: audio.AudioDevice, what: str) -> BackendError:
    """The error of a stream on ``device`` that stalled (``what`` says how it showed)."""
    return BackendError(f"audio: the stream on device {device} stalled: {what} (device hung or server stopped); "
                        "the stream is abandoned, not closed: restart the program to use audio again")
