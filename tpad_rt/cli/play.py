"""``tpad-rt play TEXTURE``: INTERIM, until the real-time audio engine lands.

Renders like ``tpad-rt render`` (same options, minus ``--out``), paced to real time,
into ``--output`` (default ``sim://``) with a live status line on a terminal, then the
render summary; ``--record FILE.npz`` also writes a recording. The first line says
that no audio engine is used. Ctrl-C stops cleanly: the drive ramps down, the summary
and the recording are still written, exit status 0. Everything specific to this stand-in
is in this module; the real-time engine replaces it whole.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import time
from pathlib import Path
from types import FrameType
from typing import Any

from rich.console import Console
from rich.live import Live
from rich.text import Text

from tpad_rt.cli.render import DEFAULT_INPUT, add_session_arguments, open_session, summary_lines
from tpad_rt.errors import ConfigError
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG
from tpad_rt.offline import OfflineRender
from tpad_rt.recording import Recording, write_recording

#: Seconds between status line updates.
STATUS_PERIOD_S = 0.1


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``play``."""
    parser = subparsers.add_parser(
        "play",
        help="render a texture in real time (interim: to sim:// until the audio engine lands)",
        description="Render TEXTURE for the finger path of --input, paced in real time, with a live status "
        "line. Interim: renders offline to --output (default sim://); Ctrl-C stops.",
    )
    add_session_arguments(parser, input_default=DEFAULT_INPUT)
    parser.add_argument("--record", metavar="FILE.npz", help="also write a recording")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Play (module docstring); 0 on success, also when stopped by Ctrl-C."""
    record = Path(args.record) if args.record else None
    if record is not None and record.suffix.lower() != ".npz":
        raise ConfigError(f"--record: must end in .npz, got '{args.record}'")
    console = Console(soft_wrap=True, highlight=False, markup=False, emoji=False)
    console.print(f"no audio engine yet: rendering to {args.output} from {args.input} (real-time pacing)")
    with contextlib.ExitStack() as stack:
        session = open_session(args, stack, keep_drive=record is not None, endless_ok=True)
        started = time.perf_counter()
        stopped = _paced(session.render, console, session.metadata)
        wall_s = time.perf_counter() - started
    result = session.render.result()
    for line in summary_lines(result, session.metadata, wall_s, session.render.pipeline.texture):
        console.print(line)
    if stopped:
        console.print("stopped by Ctrl-C")
    if record is not None and result.drive is not None:
        write_recording(record, Recording(result.fs_hz, result.drive, result.blocks, session.metadata))
        console.print(f"wrote {record}")
    return 0


def _paced(render: OfflineRender, console: Console, metadata: dict[str, Any]) -> bool:
    """Render every block no faster than real time; True if Ctrl-C stopped it (then the ramp tail is rendered)."""
    stop_requested = False

    def request_stop(signum: int, frame: FrameType | None) -> None:
        nonlocal stop_requested
        stop_requested = True

    seconds_per_block = render.block_frames / render.pipeline.fs_hz
    previous = signal.signal(signal.SIGINT, request_stop)
    live = Live(console=console, auto_refresh=False) if console.is_terminal else contextlib.nullcontext()
    if isinstance(live, Live):
        console.print(Text(STATUS_HEADER, style="dim"))
    try:
        with live:
            started = time.perf_counter()
            next_status = started
            while not render.done and not stop_requested:
                render.step()
                now = time.perf_counter()
                ahead_s = render.blocks_done * seconds_per_block - (now - started)
                if ahead_s > 0.005:
                    time.sleep(ahead_s)
                if isinstance(live, Live) and now >= next_status:
                    live.update(status_text(render.latest, metadata), refresh=True)
                    next_status = now + STATUS_PERIOD_S
            render.stop_early()
            while not render.done:
                render.step()
    finally:
        signal.signal(signal.SIGINT, previous)
    return stop_requested


#: Column header of the status line (same widths as :func:`status_text`).
STATUS_HEADER = "    time  finger (x, y), speed        μ' target→got drive     power"


def status_text(row: dict[str, float], metadata: dict[str, Any]) -> Text:
    """One status line (under 80 columns): time, finger, target→achieved friction, volts and power vs limits."""
    flags = int(row["saturated"])
    finger = "lifted" if flags & FLAG_WATCHDOG else (
        f"({row['x_mm']:5.1f},{row['y_mm']:5.1f}) mm {row['speed_mm_s']:3.0f} mm/s")
    friction = f"{row['target_mu']:.2f}" + (f"→{row['achieved_mu']:.2f}" if "achieved_mu" in row else "")
    text = Text(f"{row['t']:6.2f} s  {finger:<27} {friction:<13} "
                f"{row['voltage_v']:4.1f}/{metadata['max_voltage_v']:g} V "
                f"{row['power_w']:4.2f}/{metadata['power_budget_w']:g} W")
    if flags & (FLAG_VOLTAGE | FLAG_POWER):
        text.append(" SAT", style="bold red")
    return text
