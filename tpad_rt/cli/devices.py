"""``tpad-rt devices``: the audio output devices with the rates they accept, and the serial ports.

One line per audio output device: its index (for ``audio://INDEX``), name, host API,
output channels and the rates among ``tpad_rt.outputs.audio.CANDIDATE_RATES`` it
accepts for float32 output; then one line per serial port (device path and
description). A port the system describes no further (pyserial's "n/a": a built-in
UART's slot, not a USB adapter) is listed, in words, unless the kernel found no UART
there (its type in ``/sys/class/tty/NAME/type`` is 0) or it has no device file: those
are named in one line as left out. No port is opened to list it (opening a serial port
raises its DTR and RTS lines, closing drops them). A missing PortAudio is said in one
line (the serial ports are still listed) and ends with status 1.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

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
#: Where the kernel describes each terminal device: ``NAME/type`` is a serial port's UART type, 0 for none.
SYS_CLASS_TTY = Path("/sys/class/tty")


def serial_lines(ports: list[tuple[str, str]] | None = None, sys_class_tty: Path = SYS_CLASS_TTY) -> list[str]:
    """One line per serial port ``(device, description)`` (default: pyserial's, sorted); an UNDESCRIBED one only
    when there is a UART behind it as ``sys_class_tty`` has it (module docstring), then one line naming those left
    out. Opens none of them."""
    if ports is None:
        ports = sorted((port.device, port.description) for port in list_ports.comports())
    lines, left_out = [], []
    for device, description in ports:
        if description != UNDESCRIBED:
            lines.append(f"  {device}: {description}")
        elif not os.path.exists(device) or _uart_type(device, sys_class_tty) == 0:
            left_out.append(device)
        elif os.access(device, os.R_OK | os.W_OK):
            lines.append(f"  {device}: a built-in serial port (not a USB adapter; the system describes it no further)")
        else:
            lines.append(f"  {device}: a built-in serial port you may not open (no read and write permission; the "
                         "dialout group may)")
    lines = lines or ["  none"]
    if left_out:
        lines.append(f"  (left out: {', '.join(left_out)}: built-in serial port slots with no hardware behind them)")
    return lines


def _uart_type(device: str, sys_class_tty: Path) -> int | None:
    """The kernel's UART type of the serial port at ``device`` (0: none found there), read from ``sys_class_tty``
    without opening the port; None when the kernel gives none (not a serial core port)."""
    try:
        return int((sys_class_tty / Path(os.path.realpath(device)).name / "type").read_text())
    except (OSError, ValueError):
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
