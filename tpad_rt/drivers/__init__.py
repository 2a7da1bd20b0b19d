"""Drivers: what runs the render callback for each kind of output (docs/realtime.md).

API map
-------
open_driver(url, *, device, rate_hz, block_frames, options, stall_timeout_s) -> Driver
    the driver for ``url``'s output, by what its scheme declares it runs on
    (:class:`tpad_rt.outputs.Runs`); ConfigError as :func:`tpad_rt.outputs.output_kind`
Driver
    base class: ``rate_hz``, ``block_frames``, ``options``, ``consumes``, ``channels``,
    ``channel``; ``prepare()``, ``warm(table)``, ``open(pipeline)``, ``start(table)``,
    ``poll(table)``, ``close(ramp_ms)``, ``stats()``, ``stream_time_s()``

Drivers (one module each): :class:`~tpad_rt.drivers.audio_callback.AudioCallbackDriver`
(PortAudio calls the native callback), :class:`~tpad_rt.drivers.serial_stream.SerialStreamDriver`
(the GIL-free envelope streamer), :class:`~tpad_rt.drivers.paced.PacedDriver` (a Python
thread hands blocks to a paced :class:`tpad_rt.outputs.Output`).
"""

from __future__ import annotations

from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.outputs import Runs, output_kind
from tpad_rt.pipeline import RenderOptions


def open_driver(url: str, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                stall_timeout_s: float) -> Driver:
    """The driver of the output ``url`` names, for ``device`` at ``rate_hz`` (Hz) in blocks of ``block_frames``
    (either may be replaced by what the URL asks for); ConfigError for a bad URL."""
    parsed, kind = output_kind(url)
    driver: Driver
    if kind.runs is Runs.CALLBACK:
        from tpad_rt.drivers.audio_callback import AudioCallbackDriver

        driver = AudioCallbackDriver(parsed, device=device, rate_hz=rate_hz, block_frames=block_frames,
                                     options=options, stall_timeout_s=stall_timeout_s)
    elif kind.runs is Runs.STREAM:
        from tpad_rt.drivers.serial_stream import SerialStreamDriver

        driver = SerialStreamDriver(parsed, device=device, rate_hz=rate_hz, block_frames=block_frames,
                                    options=options)
    else:
        from tpad_rt.drivers.paced import PacedDriver

        driver = PacedDriver(parsed, device=device, rate_hz=rate_hz, block_frames=block_frames, options=options)
    if driver.consumes is not kind.consumes:  # the pipeline renders what the driver says: they must agree
        raise TypeError(f"{parsed.scheme}:// consumes {kind.consumes.value}, but its driver "
                        f"{type(driver).__name__} renders {driver.consumes.value}")
    return driver


__all__ = ["Driver", "open_driver"]
