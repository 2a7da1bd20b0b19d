"""The serial driver on the virtual link, as the tests drive it: no Renderer, no thread, no wall clock.

``VirtualRun(link)`` builds what the Renderer builds for ``serial://`` (a Pipeline
rendering the envelope, its CallbackTable, a SerialStreamDriver whose line is the
:class:`tpad_rt.amp.virtual_link.VirtualLink`), and :meth:`VirtualRun.start`,
:meth:`VirtualRun.swipe`, :meth:`VirtualRun.stop` do what the Renderer does, on the
link's virtual clock: the finger's samples are events on it, stamped as the Renderer stamps
them (its ``now_s``: the stream time of the sample the output plays now, by the streamer's
estimate of the amplifier's play position, while the streamer renders ``buffer_ms`` ahead of it), and stop waits out
the drive's ramp on it (the driver's own wait) before the driver closes.
"""

from __future__ import annotations

import threading
from pathlib import Path

from tpad_rt.amp.virtual_link import VirtualLink
from tpad_rt.device import Device
from tpad_rt.drivers.serial_stream import SerialStreamDriver
from tpad_rt.kernel import amp_stream
from tpad_rt.outputs import output_kind
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

REPO = Path(__file__).resolve().parents[1]
GRATING = REPO / "textures" / "grating.yaml"
DEVICE = Device.default()
#: A finger sample every this many ns while swiping (an application's 2 ms).
PUSH_PERIOD_NS = 2_000_000


class VirtualRun:
    """A ``serial://`` run on ``link`` (URL options as ``query``), for ``device`` rendering ``texture``."""

    def __init__(self, link: VirtualLink, *, device: Device = DEVICE, texture: Path = GRATING, query: str = "",
                 options: RenderOptions = RenderOptions()):
        self.link = link
        self.clock = link.clock
        parsed, _ = output_kind(f"serial://{link.name}{'?' + query if query else ''}")
        self.driver = SerialStreamDriver(parsed, device=device, rate_hz=192000, block_frames=64, options=options,
                                         clock=link.clock, open_line=lambda target: link)
        compiled = load_compiled(texture)
        self.pipeline = Pipeline(device, compiled, self.driver.rate_hz, options=self.driver.options,
                                 envelope_output=True)
        self.table = CallbackTable(self.pipeline.arrays, compiled)
        self.failure: BaseException | None = None

    @property
    def amp_link(self):  # type: ignore[no-untyped-def]
        """The driver's AmpLink (open between start() and stop())."""
        return self.driver.link

    def start(self) -> VirtualRun:
        """Open the link (the handshake, on the clock) and start the stream; an error closes the driver (STOP if
        START went out), as Renderer.start does, and is raised."""
        self.driver.warm(self.table.copy())
        try:
            self.driver.open(self.pipeline)
            self.pipeline.start()
            self.driver.start(self.table)
        except BaseException:
            self.pipeline.stop()
            self.driver.close(self.driver.options.ramp_ms)
            raise
        return self

    def swipe(self, seconds: float, speed_mm_s: float = 50.0, force_n: float = 0.5, x0_mm: float = 20.0) -> None:
        """Slide a finger at ``speed_mm_s`` for ``seconds`` of the clock from now, a sample every PUSH_PERIOD_NS,
        each at the stream's time; the clock ends ``seconds`` later."""
        start_ns = self.clock.now_ns()
        end_ns = start_ns + round(seconds * 1e9)
        for at_ns in range(start_ns, end_ns, PUSH_PERIOD_NS):
            self.clock.at(at_ns, lambda at_ns=at_ns: self._push(x0_mm + speed_mm_s * (at_ns - start_ns) * 1e-9,
                                                                force_n))
        self.run_until(end_ns)

    def _push(self, x_mm: float, force_n: float) -> None:
        t_s = max(self.playing_time_s(), self.pipeline.last_time_s)
        self.pipeline.push_finger(t_s, x_mm, 20.0, force_n)

    def playing_time_s(self) -> float:
        """The stream time (s) of the sample at the output now, as Renderer.now_s has it on a real port (the block
        records' DAC time: the streamer's estimate of the amplifier's play position), on the link's clock; the
        stream's next sample before the stream runs."""
        amp_link = self.driver.link
        if amp_link is None or not amp_link.streaming:
            return self.pipeline.stream_time_s
        return float(amp_stream.play_position(amp_link.link, self.clock.now_ns())) / self.pipeline.fs_hz

    def run_until(self, t_ns: int) -> None:
        """Advance the clock to ``t_ns`` (ns), the stream and the amplifier running on the way."""
        self.clock.advance_to(t_ns)

    def run_for(self, seconds: float) -> None:
        """Advance the clock ``seconds`` (s)."""
        self.run_until(self.clock.now_ns() + round(seconds * 1e9))

    def stop(self) -> BaseException | None:
        """What Renderer.stop does: ramp the drive down, let the stream render the ramp and a block past it (the
        driver's own wait, on the link's clock; none once the stream failed), then close the driver (STOP, its
        ACK); the driver's failure, if any."""
        self.pipeline.stop()
        ended = threading.Event()
        if self.driver.poll(self.table) is not None:
            ended.set()
        self.driver.wait_silent(self.table, ended)
        self.failure = self.driver.close(self.driver.options.ramp_ms)
        return self.failure

    def stats(self) -> dict:
        """The link's and the amplifier's counters (AmpLink.stats)."""
        return self.driver.stats()["amplifier"]
