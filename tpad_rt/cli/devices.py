"""``tpad-rt devices``: the audio output devices with the rates they accept, and the serial ports.

One line per audio output device: its index (for ``audio://INDEX``), name, host API,
output channels and the rates among ``tpad_rt.outputs.audio.CANDIDATE_RATES`` it
accepts for float32 output; then one line per serial port (device path and
description). A missing PortAudio is said in one line (the serial ports are still
listed) and ends with status 1.
"""

from __future__ import annotations

import argparse

from serial.tools import list_ports

from tpad_rt.cli.arguments import Subparsers
from tpad_rt.errors import BackendError
from tpad_rt.outputs import audio


def add_parser(subparsers: Subparsers) -> None:
    """Register ``devices``."""
    parser = subparsers.add_parser(
        "devices",
        help="list audio output devices (with the rates they accept) and serial ports",
        description="List the audio output devices PortAudio sees, with the sample rates each accepts, "
        "and the serial ports. A JACK server must run before this command to be listed.",
    )
    parser.set_defaults(func=run)


def audio_lines() -> list[str]:
    """One line per audio output device; BackendError when PortAudio is missing."""
    lines = []
    for device in audio.output_devices():
        rates = audio.accepted_rates(device, device.channels)
        accepted = ", ".join(f"{rate}" for rate in rates) if rates else "none of the usual rates"
        lines.append(f"  {device.index}: {device.name} ({device.host_api}), {device.channels} out, "
                     f"rates {accepted} Hz")
    return lines or ["  none"]


def serial_lines() -> list[str]:
    """One line per serial port."""
    ports = sorted(list_ports.comports(), key=lambda port: port.device)
    return [f"  {port.device}: {port.description}" for port in ports] or ["  none"]


def run(args: argparse.Namespace) -> int:
    """List the devices; 1 when PortAudio is missing, else 0."""
    status = 0
    print("audio output devices (audio://INDEX or audio://NAME):")
    try:
        print("\n".join(audio_lines()))
    except BackendError as error:
        print(f"  {error}")
        status = 1
    print("serial ports (serial://PORT):")
    print("\n".join(serial_lines()))
    return status
