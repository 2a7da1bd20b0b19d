"""``tpad-rt devices``: the audio output devices with the rates they accept, and the serial ports.

One line per audio output device: its index (for ``audio://INDEX``), name, host API,
output channels and the rates among ``tpad_rt.outputs.audio.CANDIDATE_RATES`` it
accepts for float32 output; then one line per serial port (device path and
description). A port the system describes no further (pyserial's "n/a": a built-in
UART's slot, not a USB adapter) is listed, in words, only when it opens; the slots
that do not (no hardware there) are named in one line as left out. A missing PortAudio
is said in one line (the serial ports are still listed) and ends with status 1.
"""

from __future__ import annotations

import argparse
import errno
import os

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


#: pyserial's description of a port it knows nothing about (a built-in UART's slot).
UNDESCRIBED = "n/a"


def serial_lines(ports: list[tuple[str, str]] | None = None) -> list[str]:
    """One line per serial port ``(device, description)`` (default: pyserial's, sorted); an UNDESCRIBED one only
    when it opens (module docstring), then one line naming those left out."""
    if ports is None:
        ports = sorted((port.device, port.description) for port in list_ports.comports())
    lines, left_out = [], []
    for device, description in ports:
        if description != UNDESCRIBED:
            lines.append(f"  {device}: {description}")
            continue
        problem = _open_problem(device)
        if problem is None:
            lines.append(f"  {device}: a built-in serial port (not a USB adapter; the system describes it no further)")
        elif problem.errno in (errno.EACCES, errno.EPERM):
            lines.append(f"  {device}: a built-in serial port you may not open ({problem.strerror}; the dialout "
                         "group may)")
        else:
            left_out.append(device)
    lines = lines or ["  none"]
    if left_out:
        lines.append(f"  (left out: {', '.join(left_out)}: built-in serial port slots with no hardware answering)")
    return lines


def _open_problem(device: str) -> OSError | None:
    """Why ``device`` does not open for reading and writing (without becoming the controlling terminal or
    waiting for a carrier), or None when it does (it is closed again at once)."""
    try:
        descriptor = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as error:
        return error
    os.close(descriptor)
    return None


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
