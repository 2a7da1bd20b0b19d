"""``tpad-rt amp emulate``: a software serial amplifier that follows docs/amp-protocol.md (version 2).

The emulator is an amplifier a host can talk to without hardware. By default it opens a
new pseudo-terminal and prints, as its first line, ``amplifier emulator on /dev/pts/N``:
a host opens that path as its serial port (``serial:///dev/pts/N``). It keeps its own
end of the terminal open, so a host may close and reopen the port. ``--port PATH`` uses
an existing serial device instead (raw mode, 921600 baud).

It answers HELLO with INFO (firmware ``tpad-emu 1.0``; envelope rates 8000 and 16000 Hz;
carriers 10-80 kHz, widened to take in the device's resonance, in 10 mHz steps; full
scale 1.25 x the device's ``max_voltage_v``, clamp at it; a 1024-sample buffer, frames of
up to 256 samples, a 50 ms watchdog with a 10 ms ramp, STATUS every 5 ms; current,
voltage and phase measured; an overcurrent trip at 1.5 x the current at the clamp at
resonance), and enforces every amplifier rule A1-A8. Envelope samples play in real time
at their due times on the monotonic clock; each drives the device's simulated plate
(``--device``, default the shipped default device, at a contact force of 0.5 N, or ``--force-n``), whose
circuit gives the measured current and phase. The watchdog trips 38 ms after the last
frame the emulator read (A4's 40 ms less 2 ms for its own reading latency), so the output
is 0 within 50 ms of the frame's arrival. It asks for real-time scheduling (SCHED_FIFO),
standing in for a microcontroller that nothing else delays; where the system refuses,
a note on stderr says so. Should the machine be too busy for it to keep time (a tick
20 ms late while playing), a note on stderr says so.

It ends on SIGTERM or SIGINT (Ctrl-C), after ``--duration``, or at a ``disconnect`` fault:
the output ramps to 0, ``--record FILE.npz`` is written (through a temporary file), and a
one-line summary of the counters follows, with exit status 0. The recording holds one
entry per applied envelope sample: ``t_s`` (time.monotonic() when applied), ``envelope_v``
(signed volts, after clamp and slew), ``carrier_hz``, ``index`` (stream index, -1 for
none: a held or ramped sample, or a missing one played as 0), ``plate_amplitude_um`` (the plate's mean vibration
amplitude over the sample), ``state`` (STATUS's codes, after the sample); and the scalars
``frames_ok``, ``frames_bad``, ``frames_rejected``, ``sequence_gaps``, ``underruns``,
``watchdog_trips``, ``faults`` (the counters since the last HELLO), ``watchdog_trip_t_s``
(time.monotonic() of each of those trips), ``envelope_hz`` (the last START's, 0 if none),
``full_scale_mv``, ``max_mv``, ``slew_mv_per_ms``, ``truncated``.
It keeps at most 10 minutes at 16 kHz (a note on stderr says when it stops keeping).

``--fault SPEC`` (repeatable) injects faults, listed in ``--help``; ``--seed`` makes the
random ones repeatable. A bad flag, fault, device file, recording path or port ends in
one line on stderr and exit status 1.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import signal
import sys
import textwrap
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import TYPE_CHECKING

from tpad_rt.cli.arguments import Subparsers, number, whole
from tpad_rt.clock import MonotonicClock
from tpad_rt.errors import ConfigError
from tpad_rt.limits import DEFAULT_FORCE_N, MAX_FORCE_N, MAX_INPUT_S

if TYPE_CHECKING:  # the emulator's plate is the kernels': the functions import it when they run
    from tpad_rt.amp.emulator import FaultPlan

#: Longest delay:MS fault (ms).
MAX_DELAY_MS = 10_000.0

_RATE = number(0, True, 1, "a probability")
_SECONDS = number(0, True, MAX_INPUT_S, "s")
#: Each fault: its arguments (name, parser) and what it does.
FAULTS: dict[str, tuple[tuple[tuple[str, Callable[[str], float]], ...], str]] = {
    "drop": ((("RATE", _RATE),), "drop each received byte with probability RATE (0 to 1)"),
    "corrupt": ((("RATE", _RATE),), "flip one random bit of each received byte with probability RATE (0 to 1)"),
    "delay": ((("MS", number(0, True, MAX_DELAY_MS, "ms")),),
              f"hand every received byte on MS ms late (0 to {MAX_DELAY_MS:g})"),
    "stall": ((("AT_S", _SECONDS), ("FOR_S", _SECONDS)), "read nothing from AT_S s on, for FOR_S s (repeatable)"),
    "overcurrent": ((("AT_S", _SECONDS),),
                    "an overcurrent fault at AT_S s (A6: ramp to 0 within 1 ms, FAULT until HELLO; repeatable)"),
    "disconnect": ((("AT_S", _SECONDS),), "close the port at AT_S s, then end as on SIGTERM"),
}
#: Faults that may be given more than once.
_REPEATABLE = ("stall", "overcurrent")


def _syntax(kind: str) -> str:
    return ":".join((kind, *(name for name, _ in FAULTS[kind][0])))


def fault_spec(text: str) -> tuple[str, tuple[float, ...]]:
    """An argparse type: ``KIND:VALUE[:VALUE]`` (FAULTS) as ``(kind, values)``."""
    kind, *fields = text.split(":")
    if kind not in FAULTS:
        raise argparse.ArgumentTypeError(
            f"unknown fault '{kind}' in '{text}'; one of {', '.join(_syntax(name) for name in FAULTS)}")
    arguments = FAULTS[kind][0]
    if len(fields) != len(arguments):
        raise argparse.ArgumentTypeError(f"fault {kind} is written {_syntax(kind)}, got '{text}'")
    values = []
    for (name, parse), field in zip(arguments, fields):
        try:
            values.append(parse(field))
        except argparse.ArgumentTypeError as error:
            raise argparse.ArgumentTypeError(f"{kind} {name} {error}") from None
    return kind, tuple(values)


def fault_plan(specs: list[tuple[str, tuple[float, ...]]], seed: int) -> FaultPlan:
    """The FaultPlan of the parsed ``--fault`` specs; ConfigError when a single-valued fault is given twice."""
    from tpad_rt.amp.emulator import FaultPlan

    given: dict[str, list[tuple[float, ...]]] = {}
    for kind, values in specs:
        given.setdefault(kind, []).append(values)
    for kind, occurrences in given.items():
        if len(occurrences) > 1 and kind not in _REPEATABLE:
            raise ConfigError(f"--fault {kind} given {len(occurrences)} times; it may be given once")
    first = {kind: occurrences[0][0] for kind, occurrences in given.items()}
    return FaultPlan(
        drop_rate=first.get("drop", 0.0), corrupt_rate=first.get("corrupt", 0.0),
        delay_s=first.get("delay", 0.0) / 1000,
        stalls_s=tuple((at, span) for at, span in given.get("stall", [])),
        overcurrent_at_s=tuple(at for (at,) in given.get("overcurrent", [])),
        disconnect_at_s=first.get("disconnect"), seed=seed,
    )


def add_parser(subparsers: Subparsers) -> None:
    """Register ``amp`` and its action ``emulate``."""
    parser = subparsers.add_parser(
        "amp",
        help="serial amplifier tools: emulate a protocol amplifier (docs/amp-protocol.md)",
        description="Serial amplifier tools (docs/amp-protocol.md).",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    emulate = actions.add_parser(
        "emulate",
        help="a software amplifier on a new pty (or --port), following docs/amp-protocol.md",
        description=textwrap.fill(
            "Run a software amplifier that follows docs/amp-protocol.md (version 2). It prints 'amplifier "
            "emulator on PATH' first (PATH: a new pty, or --port), serves the protocol in real time with the "
            "device's simulated plate, and ends on SIGTERM, Ctrl-C, --duration or a disconnect fault: the "
            "output ramps to 0, --record is written and a summary of the counters is printed.", 79),
        epilog="faults (--fault SPEC, repeatable; times count from the emulator's start):\n"
        + "\n".join(f"  {_syntax(kind):<20} {text}" for kind, (_, text) in FAULTS.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    emulate.add_argument("--device", metavar="FILE", help="device file, or a shipped device's name such as SLG_0.4 (default: default, SLG_0.56)")
    emulate.add_argument("--port", metavar="PATH", help="serve this existing serial device instead of a new pty")
    emulate.add_argument("--record", metavar="FILE.npz",
                         help="write the applied samples and the counters here at the end (.npz)")
    emulate.add_argument("--duration", metavar="S", type=number(0, False, MAX_INPUT_S, "s"),
                         help=f"end after S seconds, at most {MAX_INPUT_S:g} (default: run until SIGTERM or Ctrl-C)")
    emulate.add_argument("--fault", metavar="SPEC", action="append", default=[], type=fault_spec,
                         help="inject a fault (see below); repeatable")
    emulate.add_argument("--force-n", metavar="N", type=number(0, True, MAX_FORCE_N, "N"), default=DEFAULT_FORCE_N,
                         help=f"contact force on the simulated plate (default {DEFAULT_FORCE_N:g}): its circuit and "
                         "plate at that force")
    emulate.add_argument("--seed", metavar="N", type=whole(2**32 - 1, "a 32-bit seed", low=0), default=0,
                         help="seed of the random faults (default 0)")
    emulate.set_defaults(func=run)


@contextlib.contextmanager
def _stop_signals() -> Iterator[threading.Event]:
    """An event set by SIGTERM or SIGINT while inside (the previous handlers come back after)."""
    event = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        event.set()

    previous = {signum: signal.signal(signum, on_signal) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield event
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


#: The SCHED_FIFO priority the emulator asks for: it stands in for a microcontroller, which nothing else on the
#: machine delays (its loop sleeps in poll between ticks; the kernel's RT throttling still bounds it).
REALTIME_PRIORITY = 10


def _realtime_priority() -> None:
    """Run at SCHED_FIFO REALTIME_PRIORITY when the system allows it, else say on stderr that the machine's
    load may delay the emulator (then its own late reads show as the host's underruns)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except (OSError, AttributeError):
        print("tpad-rt amp emulate: no real-time priority here (SCHED_FIFO refused): a busy machine can delay the "
              "emulator, and frames it reads late count as underruns", file=sys.stderr, flush=True)


_ENDINGS = {"stopped": "stopped by a signal", "duration": "ran for --duration", "disconnected": "disconnected"}


def run(args: argparse.Namespace) -> int:
    """Emulate until stopped; 0 when it ends as asked (ConfigError, BackendError for what a user can fix)."""
    from tpad_rt.amp.emulator import (
        Amplifier, Circuit, Emulator, Plate, Port, Recorder, amplifier_info, check_record_path, counters,
        recording_scalars, sim_rate_hz, write_recording,
    )
    from tpad_rt.device import Device

    device = Device.default() if args.device is None else Device.from_file(args.device)
    plan = fault_plan(args.fault, args.seed)
    if args.record is not None:
        check_record_path(args.record)
    circuit = Circuit(device, args.force_n)
    info = amplifier_info(device, circuit)
    plate = Plate(device, args.force_n, sim_rate_hz(info.carrier_max_mhz))
    recorder = Recorder() if args.record is not None else None
    with _stop_signals() as stop:  # to the end: a second signal must not cut the recording short
        port = Port.open_pty() if args.port is None else Port.open_device(args.port)
        try:
            clock = MonotonicClock()
            amplifier = Amplifier(info, circuit, plate, clock.now_ns() / 1e9, recorder, on_hello=port.discard_output)
            emulator = Emulator(amplifier, port, plan, clock, args.duration)
            # The ~150k objects of the imports would make each full collection a 70 ms stall of the real-time
            # loop, past A4's watchdog: frozen, a collection scans only what the emulator makes.
            gc.freeze()
            _realtime_priority()
            print(f"amplifier emulator on {port.name}", flush=True)
            ending = emulator.run(stop.is_set)
        finally:
            port.close()
        if recorder is not None:
            write_recording(args.record, recorder, recording_scalars(amplifier, recorder))
        summary = " ".join(f"{name}={value}" for name, value in counters(amplifier).items())
        if emulator.dropped_out_bytes:
            summary += f" ({emulator.dropped_out_bytes} bytes for a host that did not read them were dropped)"
        print(f"amplifier emulator {_ENDINGS[ending]}: {summary}", flush=True)
    return 0
