"""The ``serial://`` driver: the GIL-free streamer renders the envelope and sends it to a serial amplifier.

The amplifier makes the carrier, so the kernel renders the envelope (drive volts) at
the amplifier's envelope rate, in frames of the URL's ``frame_ms`` (docs/kernel.md
"Two stages"). The streamer (:mod:`tpad_rt.kernel.amp_stream`, run by
:class:`tpad_rt.outputs.serial_amp.AmpLink`) calls the same compiled render callback
as PortAudio does, once per frame, in one numba call that holds no GIL.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from tpad_rt.clock import Clock
from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.outputs import serial_amp
from tpad_rt.outputs.base import Consumes
from tpad_rt.outputs.serial_line import Line
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.urls import Url

#: The rate (Hz) at which RenderOptions' default control_interval gives the default control period; at an
#: envelope rate the default interval is scaled to keep that period.
DEFAULT_CONTROL_RATE_HZ = 192000


class SerialStreamDriver(Driver):
    """A ``serial://`` amplifier: ``envelope_hz`` replaces the renderer's rate, ``frame_ms`` its block (until
    the amplifier's INFO says how many samples a frame may hold); a default ``options.control_interval``
    is scaled to keep its control period. ``open_line`` opens the line to the amplifier for the URL's target
    (default: its serial port); ``clock`` must be that line's (a :class:`tpad_rt.amp.virtual_link.VirtualLink`
    and its VirtualClock run the driver on a virtual clock)."""

    consumes = Consumes.ENVELOPE

    def __init__(self, url: Url, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                 stall_timeout_s: float = 0.5, clock: Clock | None = None,
                 open_line: Callable[[serial_amp.SerialTarget], Line] | None = None):
        target = serial_amp.parse_serial_url(url)
        rate_hz = target.envelope_hz
        if options.control_interval == RenderOptions.control_interval:
            options = replace(options, control_interval=max(1, round(
                RenderOptions.control_interval * rate_hz / DEFAULT_CONTROL_RATE_HZ)))
        super().__init__(url, device=device, rate_hz=rate_hz, options=options, stall_timeout_s=stall_timeout_s,
                         clock=clock,
                         block_frames=max(1, round(target.frame_ms * 1e-3 * rate_hz)))
        self.target = target
        self._open_line = open_line
        self.link: serial_amp.AmpLink | None = None  # open between open() and close()
        self._last_link: serial_amp.AmpLink | None = None  # for stats() after close()

    def warm(self, table: CallbackTable) -> None:
        """Compile the render callback and the streamer before the port opens (the amplifier's watchdog never
        waits for a compile)."""
        super().warm(table)
        serial_amp.warm_up(table)

    def open(self, pipeline: Pipeline) -> None:
        """Open the port, make the handshake, set the carrier to the device's resonance, measure the link; the
        envelope's scale the link decided (the amplifier's full scale; the lower of its clamp and the device's
        max_voltage_v) and the achieved carrier go into the pipeline. A link too slow for the URL's frames gets
        larger ones: one line on stderr says so (and the summary; a recording's metadata has the frames in
        ``block_frames``). BackendError as AmpLink.open says."""
        line = self._open_line(self.target) if self._open_line is not None else None
        link = self.link = self._last_link = serial_amp.AmpLink.open(self.target, carrier_hz=self.device.carrier_hz,
                                                                    max_voltage_v=self.device.max_voltage_v, line=line)
        scale = link.scale  # decided once, from the INFO the handshake took (H1, H3); the streamer clamps to it
        assert scale is not None
        if link.link_note:  # the link is slower than the URL's frames need: larger frames (H11), said once here
            print(link.link_note, file=sys.stderr, flush=True)
        pipeline.set_drive(pipeline.device_drive.from_hardware(
            volts_per_full_scale=scale.full_scale_v, max_voltage_v=scale.max_v, carrier_hz=link.carrier_hz,
            source=f"amplifier {link.info.firmware!r} on {self.target.port}" if link.info else self.target.port))
        self.block_frames = link.frame_samples

    def start(self, table: CallbackTable) -> None:
        """START the amplifier at the table's next sample and stream in a thread of its own."""
        assert self.link is not None, "open() first"
        self.link.start(table, track=self.options.track, ramp_ms=self.options.ramp_ms)

    def poll(self, table: CallbackTable) -> BaseException | None:
        """The error that ended the stream (a BackendError: port lost, amplifier fault, silence...), or None."""
        link = self.link
        return link.failure() if link is not None else None

    def close(self, ramp_ms: float) -> BaseException | None:
        """End the stream with STOP and ``ramp_ms`` and close the port; the error that ended the stream, if any."""
        link, self.link = self.link, None
        if link is None:
            return None
        failure = link.failure()
        link.stop(ramp_ms)
        return failure

    def summary_lines(self, stats: dict[str, Any]) -> list[str]:
        """The amplifier's counters, and the tracking's carrier and lock, for the end of ``tpad-rt play``."""
        amplifier = stats.get("amplifier")
        if not amplifier:
            return []
        lines = [
            f"amplifier: {amplifier['firmware']}, carrier {amplifier['carrier_hz']:.2f} Hz, envelope "
            f"{amplifier['envelope_hz']} Hz; frames {amplifier['amp_frames_ok']} applied, {amplifier['amp_frames_bad']} "
            f"bad, {amplifier['amp_frames_rejected']} refused, {amplifier['amp_sequence_gaps']} sequence gaps; "
            f"{amplifier['amp_underruns']} samples underrun, {amplifier['amp_watchdog_trips']} watchdog trips"
            + ("" if amplifier["realtime"] else " (no real-time priority for the streamer here)")]
        if amplifier["link_note"]:
            lines.append(amplifier["link_note"])
        if amplifier["tracking"] != "off":
            lines.append(f"tracking ({amplifier['tracking']}): carrier now {amplifier['tracked_carrier_hz']:.2f} Hz "
                         f"after {amplifier['carrier_sets']} SET_CARRIER ({amplifier['carrier_refused']} refused); "
                         f"lock correction {amplifier['lock_offset_hz']:+.2f} Hz over {amplifier['lock_updates']} "
                         "STATUS frames")
        return lines

    def stats(self) -> dict[str, Any]:
        """``amplifier``: the link's and the amplifier's counters (AmpLink.stats), once it was opened."""
        result = super().stats()
        if self._last_link is not None:
            result["amplifier"] = self._last_link.stats()
        return result
