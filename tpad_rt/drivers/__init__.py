"""Drivers: what runs the render callback for each kind of output (docs/realtime.md).

API map
-------
open_driver(url, *, device, rate_hz, block_frames, options, stall_timeout_s) -> Driver
    the driver ``url``'s scheme names in its kind (:class:`tpad_rt.outputs.OutputKind`, ``driver``);
    ConfigError as :func:`tpad_rt.outputs.output_kind`, or for a kind whose driver is no Driver
Driver
    base class: ``rate_hz``, ``block_frames``, ``options``, ``consumes``, ``channels``,
    ``channel``, ``clock``, ``log``; ``prepare()``, ``warm(table)``, ``warm_compiles()``, ``open(pipeline)``,
    ``start(table)``, ``poll(table)``, ``wait_silent(table, ended)``, ``close(ramp_ms)``,
    ``stats()``, ``summary_lines(stats)``, ``stream_time_s()``

Drivers (one module each): :class:`~tpad_rt.drivers.audio_callback.AudioCallbackDriver`
(PortAudio calls the native callback), :class:`~tpad_rt.drivers.serial_stream.SerialStreamDriver`
(the GIL-free envelope streamer), :class:`~tpad_rt.drivers.paced.PacedDriver` (a Python
thread hands blocks to a paced :class:`tpad_rt.outputs.Output`). An output kind names its
driver; a new kind may bring its own (docs/architecture.md "Adding an output kind").
"""

from __future__ import annotations

import importlib

from tpad_rt.device import Device
from tpad_rt.drivers.base import Driver
from tpad_rt.errors import ConfigError
from tpad_rt.outputs import output_kind
from tpad_rt.pipeline import RenderOptions


def driver_class(name: str) -> type[Driver]:
    """The Driver subclass ``name`` (``"module:Class"``) names; ConfigError when it names none."""
    module_name, _, class_name = name.partition(":")
    try:
        found = getattr(importlib.import_module(module_name), class_name)
    except Exception as error:  # noqa: BLE001 - a package's driver module may raise anything on import: one message
        raise ConfigError(f"output driver {name}: not found ({error})") from None
    if not (isinstance(found, type) and issubclass(found, Driver)):
        raise ConfigError(f"output driver {name}: not a tpad_rt.drivers.Driver")
    return found


def open_driver(url: str, *, device: Device, rate_hz: int, block_frames: int, options: RenderOptions,
                stall_timeout_s: float) -> Driver:
    """The driver of the output ``url`` names, for ``device`` at ``rate_hz`` (Hz) in blocks of ``block_frames``
    (either may be replaced by what the URL asks for); ConfigError for a bad URL."""
    parsed, kind = output_kind(url)
    driver = driver_class(kind.driver)(parsed, device=device, rate_hz=rate_hz, block_frames=block_frames,
                                       options=options, stall_timeout_s=stall_timeout_s)
    if driver.consumes is not kind.consumes:  # the pipeline renders what the driver says: they must agree
        raise ConfigError(f"{parsed.scheme}:// consumes {kind.consumes.value}, but its driver "
                          f"{type(driver).__name__} renders {driver.consumes.value}")
    return driver


__all__ = ["Driver", "driver_class", "open_driver"]
