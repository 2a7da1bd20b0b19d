"""``tpad-rt play TEXTURE``: render a texture in real time on the :class:`~tpad_rt.engine.Renderer`.

``--output auto`` (default) picks an audio device that accepts ``--rate`` (a JACK
device first, then the default output), else the simulated plate ``sim://``;
``--input auto`` picks ``mouse://`` when an X display answers, else endless
back-and-forth swipes (:func:`auto_swipe`) at the speed and force the texture's file
recommends (its ``finger``; FALLBACK_SPEED_MM_S and FALLBACK_FORCE_N for a file without one), the mouse
pressing with that force. The first line says both choices and why.
A :class:`~tpad_rt.inputs.live.LiveFeed` feeds the input into the renderer; a status
panel (finger, target friction and, on an output that simulates the plate (``sim://``),
the texture under the finger and the friction the simulated plate gave, volts, power,
underflows, callback load, time) refreshes :data:`STATUS_HZ` times a second on a
terminal (nothing on a pipe). When the run's telemetry holds the plate's measurements
(:data:`PLATE_FRICTION`, which the output measured of every block it played) every
block is judged: that friction against the texture under the finger at the block's
middle; the panel and the summary count the blocks further than
DEPARTURE_TOLERANCE_MU (as ``tpad-rt render`` does). Play
ends at ``--duration``, when a finite input ends, or on Ctrl-C (exit status 0): the
drive ramps to 0 (``Renderer.stop``), a summary follows, and ``--record`` writes the
recording (the ``tpad-rt render`` format). An error (bad file or URL, missing, lost or
stalled audio device, an input failing) ends with the output ramped and closed (a lost
device's stream is abandoned: docs/realtime.md), one line on stderr and exit status 1
(``tpad_rt.cli.main``).

Limits (:mod:`tpad_rt.limits`): ``--duration`` at most MAX_INPUT_S, ``--rate`` and
``--block`` as for ``render``; ``--record`` keeps at most MAX_RECORDING_SAMPLES drive
samples in memory (349 s at 192 kHz: a longer play ends with one clear error) and
must name a regular file if it exists.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Iterator
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.table import Table

from tpad_rt.cli.arguments import Subparsers, number
from tpad_rt.cli.headroom import FingerTally, hint_lines, swipe_url
from tpad_rt.cli.render import add_session_arguments, over_cap_line, peak_text, session_options
from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.files import check_writable_target
from tpad_rt.felt import DEPARTURE_TOLERANCE_MU, judge_blocks, start_ramps
from tpad_rt.inputs import open_input
from tpad_rt.inputs.live import LiveFeed, PushFinger
from tpad_rt.inputs.mouse import INSTALL_HINT, pynput_installed, screen_size_px
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG
from tpad_rt.limits import MAX_INPUT_S, MAX_RECORDING_SAMPLES, MAX_STALL_TIMEOUT_S
from tpad_rt.drive import Consumes
from tpad_rt.outputs import audio

# The parser needs none of the file models, the device model and the kernels (tpad-rt --help starts without
# numba and pydantic): the functions import them when they run.
if TYPE_CHECKING:
    from tpad_rt.config.texture_schema import Finger
    from tpad_rt.engine import Renderer

#: The finger ``--input auto`` follows for a texture whose file recommends none (its ``finger``): speed (mm/s)
#: and force (N).
FALLBACK_SPEED_MM_S, FALLBACK_FORCE_N = 100.0, 0.5
#: Status refreshes per second.
STATUS_HZ = 5
#: The telemetry column of the friction a simulated plate gave each block (``sim://`` measures it).
PLATE_FRICTION = "achieved_mu"


@dataclass(frozen=True)
class Choice:
    """An output or input URL and why it was chosen (empty when the user named it)."""

    url: str
    reason: str = ""

    def __str__(self) -> str:
        return f"{self.url} ({self.reason})" if self.reason else self.url


def help_epilog() -> str:
    """What ``play --help`` ends with: the shipped textures by name, and every output and input URL's form."""
    from tpad_rt.shipped import texture_names  # a folder listing: nothing heavy at parser building

    return (f"TEXTURE is a YAML file or a shipped texture's name: {', '.join(texture_names())}. "
            "Outputs: audio://[DEVICE]?rate=192000&block=64 (an audio device; 'tpad-rt devices' lists them), "
            "serial://PORT?envelope_hz=16000 (a serial amplifier; 'tpad-rt amp emulate' makes one on a pty: "
            "docs/amplifiers.md), sim:// (the simulated plate), wav:///path/out.wav (the drive as a WAV file, "
            "paced in real time), null://. Inputs: scripted://swipe?speed_mm_s=30, scripted://circle, "
            "scripted://tap, scripted://still, file:///path/trajectory.csv, mouse:// (the README's URL table).")


def add_parser(subparsers: Subparsers) -> None:
    """Register ``play``."""
    parser = subparsers.add_parser(
        "play",
        help="render a texture in real time (audio device or simulated plate) with a live status",
        description="Render TEXTURE in real time for the finger of --input on --output, with a live status "
        "panel; Ctrl-C stops with a ramp and prints a summary.",
        epilog=help_epilog(),
    )
    add_session_arguments(
        parser, input_default="auto", max_duration_s=MAX_INPUT_S,
        input_help="finger input URL, or auto: mouse:// with an X display, else endless back-and-forth swipes at "
        "the speed and force the texture's file recommends (its finger; without one "
        f"{swipe_url(FALLBACK_SPEED_MM_S, FALLBACK_FORCE_N)})",
        output_default="auto", output_help="output URL (audio://[device]?..., serial://PORT?..., sim://, "
        "wav://FILE.wav, null://), or auto: an audio device that accepts --rate (JACK first), else sim://")
    parser.add_argument("--record", metavar="FILE.npz",
                        help="also write a recording (the format of render); it keeps at most "
                        f"{MAX_RECORDING_SAMPLES:,} drive samples ({MAX_RECORDING_SAMPLES // 192000} s at 192 kHz), "
                        "a longer play ends with an error")
    parser.add_argument("--stall-timeout", metavar="S", type=number(0, False, MAX_STALL_TIMEOUT_S, "s"), default=0.5,
                        help="an audio stream without a callback for S seconds has stalled (a hung device or a "
                        "stopped JACK server): play ends with an error (default 0.5)")
    parser.set_defaults(func=run)


def choose_output(requested: str, rate_hz: int) -> Choice:
    """``requested``, or for ``auto`` the first audio device accepting ``rate_hz`` (JACK, then the default
    output, then the others), else ``sim://``."""
    if requested != "auto":
        return Choice(requested)
    try:
        devices = audio.output_devices()
    except BackendError as error:
        return Choice("sim://", f"no audio: {error}")
    default = audio.portaudio()[1].Pa_GetDefaultOutputDevice()
    ranked = sorted(devices, key=lambda device: ("JACK" not in device.host_api, device.index != default))
    for device in ranked:
        if audio.accepted_rates(device, device.channels, (rate_hz,)):
            return Choice(f"audio://{device.index}", f"'{device.name}', {device.host_api}, runs {rate_hz} Hz")
    return Choice("sim://", f"no audio device runs {rate_hz} Hz")


def auto_swipe(finger: Finger) -> str:
    """Endless back-and-forth swipes along the plate at ``finger``'s speed (mm/s) and force (N)."""
    return swipe_url(finger.speed_mm_s, finger.force_n)


def choose_input(requested: str, recommended: Finger | None, force_n: float | None = None) -> Choice:
    """``requested``, or for ``auto`` ``mouse://`` when pynput is installed and an X display answers, else
    :func:`auto_swipe`: at the ``recommended`` finger's speed (mm/s) and force (N), :data:`FALLBACK_SPEED_MM_S` and
    :data:`FALLBACK_FORCE_N` when None; ``force_n`` (N, ``--force``) replaces the force."""
    if requested != "auto":
        return Choice(requested)
    from tpad_rt.config.texture_schema import Finger

    finger = recommended or Finger(speed_mm_s=FALLBACK_SPEED_MM_S, force_n=FALLBACK_FORCE_N)
    whose = "the texture's recommended finger" if recommended else "no finger in the texture's file"
    why = f"{whose}: {finger.speed_mm_s:g} mm/s under {finger.force_n:g} N"
    if force_n is not None:
        finger = finger.model_copy(update={"force_n": force_n})
        why = f"{whose}: {finger.speed_mm_s:g} mm/s, under --force {force_n:g} N"
    if not pynput_installed():
        return Choice(auto_swipe(finger), f"no pynput for the mouse: {INSTALL_HINT}; {why}")
    try:
        width, height = screen_size_px()
    except BackendError:
        return Choice(auto_swipe(finger), f"no display; {why}")
    return Choice(f"mouse://?force_n={finger.force_n:g}",
                  f"{width}x{height} screen onto the plate, left button held touches; {why}")


def run(args: argparse.Namespace) -> int:
    """Play (module docstring); 0 when it ends normally or by Ctrl-C."""
    from tpad_rt.compiling import compile_notice, ensure_compiled
    from tpad_rt.config import load_texture
    from tpad_rt.device import Device

    if args.record is not None:
        if Path(args.record).suffix.lower() != ".npz":
            raise ConfigError(f"--record: must end in .npz, got '{args.record}'")
        check_writable_target(args.record, "recordings")
    console = Console(soft_wrap=True, highlight=False, markup=False, emoji=False)
    recommended = load_texture(args.texture).finger if args.input == "auto" else None
    output, finger = choose_output(args.output, args.rate), choose_input(args.input, recommended, args.force)
    options = session_options(args)
    with contextlib.ExitStack() as compiling:
        # A first run compiles the kernels (about 10 s): say so at once, and compile everything
        # before the clock starts, so the run itself renders from its first second.
        compiling.enter_context(compile_notice())
        device = Device.default() if args.device is None else Device.from_file(args.device)
        with open_input(finger.url, device=device) as source, _sigint_event() as interrupted:
            from tpad_rt.engine import Renderer  # compiles the audio callback: only once the input is known good

            renderer = Renderer(device, output.url, texture=args.texture, rate_hz=args.rate,
                                block_frames=args.block, options=options, stall_timeout_s=args.stall_timeout)
            console.print(f"output {output}, input {finger}; "
                          + (f"{args.duration:g} s or " if args.duration else "") + "Ctrl-C stops")
            if args.record is not None:
                renderer.record(args.record, input_url=finger.url)
            ensure_compiled()  # every argument checked: compile the whole plan if the cache lacks it
            # The status line's texture under the finger loads the texture kernel (numba): after the first
            # sample when the output runs ahead-of-time code (an audio output then starts without numba).
            ahead_of_time = not renderer.driver.warm_compiles()
            if not ahead_of_time:
                renderer.texture.evaluate(np.zeros(1), np.zeros(1))
            renderer.start()
            started_s = time.monotonic()  # the session counts from the first sample: what it played, it says
            if ahead_of_time:
                renderer.texture.evaluate(np.zeros(1), np.zeros(1))
            compiling.close()
            with renderer, LiveFeed(source, _pusher(renderer, args.force), renderer.lift,
                                    clock=renderer.now_s) as feed:
                session = Session(renderer, console, started=started_s)
                _loop(session, feed, interrupted, args.duration)
                session.tick()  # the blocks since the last status period, judged while the renderer runs
    session.take_telemetry()
    for line in session.summary(interrupted.is_set()):
        console.print(line)
    if args.record is not None:
        console.print(f"wrote {args.record}")
    return 0


def _pusher(renderer: Renderer, fixed_n: float | None) -> PushFinger:
    """``renderer.push_finger``, with every sample's force replaced by ``fixed_n`` (N) when given."""
    if fixed_n is None:
        return renderer.push_finger

    def push(x_mm: float, y_mm: float, force_n: float | None = None, t: float | None = None) -> None:
        renderer.push_finger(x_mm, y_mm, fixed_n, t)

    return push


@contextlib.contextmanager
def _sigint_event() -> Iterator[threading.Event]:
    """An Event that SIGINT (Ctrl-C) sets instead of raising KeyboardInterrupt, while open."""
    event = threading.Event()

    def on_sigint(signum: int, frame: FrameType | None) -> None:
        event.set()

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield event
    finally:
        signal.signal(signal.SIGINT, previous)


def _loop(session: Session, feed: LiveFeed, interrupted: threading.Event, duration_s: float | None) -> None:
    """Refresh the status until Ctrl-C, ``duration_s`` (s), the input's end or an error (re-raised)."""
    live = Live(console=session.console, auto_refresh=False) if session.console.is_terminal else None
    with live if live is not None else contextlib.nullcontext():
        while not interrupted.wait(1 / STATUS_HZ):
            session.renderer.check()
            session.tick()
            if live is not None:
                live.update(session.panel(), refresh=True)
            if not feed.is_alive() or (duration_s is not None and session.elapsed_s() >= duration_s):
                return


@dataclass
class Session:
    """A running play (from when the renderer and the feed run): the renderer, the last telemetry row, and where the telemetry holds it the simulated plate's friction, the texture under the finger,
    and their differences."""

    renderer: Renderer
    console: Console
    started: float = field(default_factory=time.monotonic)
    latest: dict[str, float] = field(default_factory=dict)
    achieved: float | None = None
    felt: float | None = None
    judged_blocks: int = 0
    departed_blocks: int = 0
    ramp_departed_blocks: int = 0  # of departed_blocks, those in a touch's start ramp (start_ramps)
    touch_start_s: float = -math.inf  # the start of the touch the last judged block belongs to (s)
    was_touching: bool = False  # whether the last judged block was touching
    error_sum: float = 0.0
    error_max: float = 0.0
    departed_saturated_blocks: int = 0  # of departed_blocks, those the drive saturated in
    tally: FingerTally = field(default_factory=FingerTally)  # the touching blocks' finger, asks and saturation

    def elapsed_s(self) -> float:
        """Seconds since play started."""
        return time.monotonic() - self.started

    def take_telemetry(self) -> dict[str, np.ndarray]:
        """Drain the renderer's telemetry: keep the last row; the rows drained."""
        rows = self.renderer.telemetry()
        if len(rows["t"]):
            self.latest = {name: float(column[-1]) for name, column in rows.items()}
            self.tally.add(rows)
        return rows

    def tick(self) -> None:
        """One status period: drain the telemetry, then judge its blocks on the simulated plate."""
        self.judge(self.take_telemetry())

    def judge(self, rows: dict[str, np.ndarray]) -> None:
        """When ``rows`` (telemetry, oldest first) hold the friction the simulated plate gave each block
        (:data:`PLATE_FRICTION`), judge each block against the texture under the finger at its middle
        (felt.judge_blocks: touching, measured blocks, the texture clamped to the floor the kernel renders)."""
        if PLATE_FRICTION not in rows or not len(rows["t"]):
            return
        renderer = self.renderer
        achieved = rows[PLATE_FRICTION]
        judgement = judge_blocks(rows, renderer.recent_fingers(), renderer.texture,
                                 block_s=renderer.block_frames / renderer.rate_hz, mu_floor=renderer.options.mu_floor,
                                 texture_t0_s=renderer.texture_t0_s())
        felt, judged, departed = judgement.felt_mu, judgement.judged, judgement.departed
        touching = (rows["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0
        errors = np.abs(felt - achieved)[judged]
        ramping, self.touch_start_s = start_ramps(rows["t"], touching, self.ramp_window_s(), self.touch_start_s,
                                                  self.was_touching)
        self.was_touching = bool(touching[-1])
        self.judged_blocks += len(errors)
        self.departed_blocks += int(np.count_nonzero(departed))
        self.ramp_departed_blocks += int(np.count_nonzero(departed & ramping))
        saturated = (rows["saturated"].astype(np.int64) & (FLAG_VOLTAGE | FLAG_POWER)) != 0
        self.departed_saturated_blocks += int(np.count_nonzero(departed & saturated))
        if len(errors):
            self.error_sum += float(errors.sum())
            self.error_max = max(self.error_max, float(errors.max()))
        self.achieved = float(achieved[-1]) if np.isfinite(achieved[-1]) else None
        self.felt = float(felt[-1]) if judgement.known[-1] else None

    def ramp_window_s(self) -> float:
        """How long (s) a touch's start ramp lasts: the drive's fade-in (ramp_ms) and the simulated plate's
        envelope time constant at the default force after it."""
        options = self.renderer.options
        tau_s = float(self.renderer.device.envelope_time_constant_s(options.default_force_n))
        return options.ramp_ms * 1e-3 + tau_s

    def ramp_text(self) -> str:
        """How many of the departed blocks lie in a touch's start ramp ("" when none departed)."""
        if not self.departed_blocks:
            return ""
        return f"; {self.ramp_departed_blocks} of them in a touch's start ramp (the drive fading in)"

    def panel(self) -> Table:
        """The live status panel."""
        row, stats = self.latest, self.renderer.stats()
        grid = Table.grid(padding=(0, 2))
        grid.add_column(style="dim")
        grid.add_column()
        if row:
            lifted = int(row["saturated"]) & FLAG_WATCHDOG
            grid.add_row("finger", f"({row['x_mm']:5.1f}, {row['y_mm']:5.1f}) mm  {row['speed_mm_s']:4.0f} mm/s  "
                         + ("lifted" if lifted else "down"))
            grid.add_row("target friction", f"{row['target_mu']:.2f}  (what the renderer asks of the plate, at the "
                         "finger extrapolated ahead by horizon_ms)")
            if self.felt is not None:
                grid.add_row("under the finger", f"{self.felt:.2f}  (the texture where the finger last was)")
            if self.achieved is not None:
                grid.add_row("simulated plate", f"{self.achieved:.2f}  (the friction the simulated plate gives now)")
                grid.add_row("departures", f"{self.departed_blocks} of {self.judged_blocks} touching blocks further "
                             f"than {DEPARTURE_TOLERANCE_MU:g} from the texture under the finger{self.ramp_text()}")
            grid.add_row("drive", f"{row['voltage_v']:5.1f} V of {self.renderer.drive.max_voltage_v:g} V"
                         + ("  SATURATED" if int(row["saturated"]) & (FLAG_VOLTAGE | FLAG_POWER) else ""))
        grid.add_row("power", f"now {row.get('power_w', 0.0):.3f} W, mean {stats['power_mean_w']:.3f} W, "
                     f"peak {stats['power_peak_w']:.3f} W of {stats['power_budget_w']:g} W")
        grid.add_row("callbacks", f"{stats['callbacks']}, {stats['underflows']} underflows, "
                     f"load p99 {100 * stats['callback_load_p99']:.1f} % of a block")
        grid.add_row("time", f"{self.elapsed_s():.1f} s, {stats['played_s']:.1f} s of drive played"
                     + self.stalled_note(stats).upper())
        return grid

    def stalled_note(self, stats: dict[str, Any]) -> str:
        """``; the output stalled for S s`` when the output took less drive than the time that passed (more
        than two blocks' worth and 5 %), else empty: what the summary and the panel both say."""
        missing_s = self.elapsed_s() - stats["played_s"]
        if missing_s <= max(2 * stats["block_frames"] / stats["rate_hz"], 0.05 * self.elapsed_s()):
            return ""
        return f"; the output stalled for {missing_s:.2f} s"

    def summary(self, interrupted: bool) -> list[str]:
        """The end-of-play summary from the renderer's stats (and the judged friction, where measured)."""
        stats = self.renderer.stats()
        blocks = max(stats["blocks"], 1)
        drive = self.renderer.drive
        amplifier = drive.consumes is Consumes.ENVELOPE  # frames to an amplifier that makes the carrier
        block, output = ("frame", "amplifier") if amplifier else ("callback", "DAC")
        lines = [
            f"played {stats['played_s']:.2f} s of drive in {self.elapsed_s():.2f} s"
            + (" (stopped by Ctrl-C)" if interrupted else "")
            + f": {stats['callbacks']} {block}s of {stats['block_frames']} {'samples' if amplifier else 'frames'} "
            f"at {stats['rate_hz']} Hz, "
            f"{stats['underflows']} " + ("sent late" if amplifier else "underflows") + self.stalled_note(stats),
            f"{block} compute: p50 {stats['compute_us_p50']:.1f} us, p99 {stats['compute_us_p99']:.1f} us "
            f"({100 * stats['callback_load_p99']:.1f} % of a {block})",
            f"push-to-output latency: p50 {stats['latency_ms_p50']:.2f} ms, p99 {stats['latency_ms_p99']:.2f} ms"
            + (f" (of which the host reports {stats['dac_delay_ms']:.2f} ms from {block} to {output})"
               if stats["dac_delay_ms"] > 0 else ""),
            "drive: " + peak_text(stats["voltage_peak_v"], drive.max_voltage_v, stats["kick_blocks"],
                                  stats["voltage_peak_outside_kicks_v"],
                                  "" if drive.source == "device file" else drive.source)
            + "; saturated "
            f"{100 * stats['voltage_saturated'] / blocks:.1f} % of blocks (voltage), "
            f"{100 * stats['power_saturated'] / blocks:.1f} % (power)",
            f"power: mean {stats['power_mean_w']:.3f} W, peak {stats['power_peak_w']:.3f} W "
            f"(cap {stats['power_budget_w']:g} W, average budget {stats['power_avg_w']:g} W)",
        ]
        if stats["over_cap_blocks"]:
            lines.append(over_cap_line(stats["over_cap_blocks"], stats["plate_peak_w"]))
        if stats["faults"]:
            lines.append(f"faults: {stats['faults']} ({stats['fault_steps']} control steps, "
                         f"{stats['fault_blocks']} blocks; {', '.join(stats['fault_causes'])}): the drive ramped to 0 "
                         "each time and came back with the next valid data (docs/kernel.md \"Faults\")")
        if stats["lead_over_blocks"]:
            lines.append(lead_over_line(stats["lead_over_blocks"], stats["lead_bound_ms"], block, output))
        lines += self.renderer.driver.summary_lines(stats)
        if self.judged_blocks:
            lines.append(f"friction |texture under the finger - simulated plate| over {self.judged_blocks} touching "
                         f"blocks: mean {self.error_sum / self.judged_blocks:.4f}, max {self.error_max:.4f}; "
                         f"departures: {self.departed_blocks} blocks "
                         f"({100 * self.departed_blocks / self.judged_blocks:.1f} %) further than "
                         f"{DEPARTURE_TOLERANCE_MU:g}{self.ramp_text()}")
        lines += hint_lines(self.tally, self.renderer.device, self.renderer.drive.max_voltage_v,
                            stats["power_budget_w"], self.judged_blocks, self.departed_blocks,
                            self.departed_saturated_blocks)
        return [line.replace("nan", "n/a") for line in lines]


def lead_over_line(blocks: int, bound_ms: float, block: str, output: str) -> str:
    """The summary's line for ``blocks`` {block}s whose reported delay to the {output} was above the ``bound_ms``
    (ms) the output can have, or not a number: the finger watchdog took the bound for them."""
    return (f"the host reported a delay from {block} to {output} above the {bound_ms:.2f} ms the output can have "
            f"(or not a number) for {blocks} {block}s: the finger watchdog took {bound_ms:.2f} ms for them")
