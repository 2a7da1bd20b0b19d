"""``tpad-rt render TEXTURE --input URL --out FILE.npz|FILE.wav``: render offline.

Runs the pipeline over the input's finger samples as fast as it goes (no audio
device), into the output (default ``sim://``, the simulated plate, so the recording
says what friction the finger would feel). ``--out FILE.npz`` writes a recording
(:mod:`tpad_rt.recording`: drive, per-block telemetry, plate amplitude and achieved
friction, metadata); ``--out FILE.wav`` writes the drive as a 32-bit float WAV. A
progress bar shows on a terminal; a summary follows.

The session helpers here (:func:`add_session_arguments`, :func:`open_session`,
:func:`summary_lines`) are the offline session's; ``tpad-rt play`` reuses the arguments.

Limits (:mod:`tpad_rt.limits`), refused in one line before anything is allocated:
``--rate`` at most MAX_RATE_HZ, ``--block`` 1 to MAX_BLOCK_FRAMES, ``--duration`` (or
the input's own end) at most MAX_RENDER_S, at most MAX_RENDER_BLOCKS blocks, and for
``.npz`` at most MAX_RECORDING_SAMPLES drive samples (checked before the outputs open
and the kernel warms up). ``--out`` must be a regular file if it exists.
"""

from __future__ import annotations

import argparse
import contextlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

from tpad_rt.cli.arguments import Subparsers, number, whole
from tpad_rt.errors import ConfigError
from tpad_rt.felt import DEPARTURE_TOLERANCE_MU, judge_blocks
from tpad_rt.files import check_writable_target
from tpad_rt.inputs import open_input
from tpad_rt.kernel.layout import (
    FLAG_FAULT, FLAG_POWER, FLAG_SHAPER_LIMIT, FLAG_VOLTAGE, FLAG_WATCHDOG, MODEL_GUARD_FRACTION,
)
from tpad_rt.limits import MAX_BLOCK_FRAMES, MAX_FORCE_N, MAX_RATE_HZ, MAX_RECORDING_SAMPLES, MAX_RENDER_S
from tpad_rt.outputs import Capability, open_output, output_kind
from tpad_rt.recording import Recording, run_metadata, write_recording

# The parser needs none of these (tpad-rt --help starts without numba and pydantic): the functions import
# them when they run.
if TYPE_CHECKING:
    from tpad_rt.offline import OfflineRender, RenderResult
    from tpad_rt.pipeline import RenderOptions
    from tpad_rt.texture import CompiledTexture

DEFAULT_OUTPUT = "sim://"
INPUT_HELP = "finger input, e.g. scripted://swipe?speed_mm_s=100 or file:///path/trajectory.csv"
OUTPUT_HELP = "output: sim://, wav:///path/out.wav or null://"
#: Highest --power-budget and --power-avg (W): the highest power_budget_w a device file may give.
MAX_POWER_W = 1000.0


def add_session_arguments(parser: argparse.ArgumentParser, *, input_default: str | None = None,
                          input_help: str = INPUT_HELP, output_default: str = DEFAULT_OUTPUT,
                          output_help: str = OUTPUT_HELP, max_duration_s: float = MAX_RENDER_S) -> None:
    """The arguments ``render`` and ``play`` share (``--input`` required when ``input_default`` is None).

    ``input_help`` and ``output_help`` describe ``--input`` and ``--output`` (their defaults
    are appended); ``--duration`` is bounded by ``max_duration_s`` (s); ``--rate`` and
    ``--block`` by MAX_RATE_HZ and MAX_BLOCK_FRAMES.
    """
    parser.add_argument("texture", metavar="TEXTURE", help="texture file (YAML)")
    parser.add_argument("--input", metavar="URL", required=input_default is None, default=input_default,
                        help=input_help + (f" (default {input_default})" if input_default else ""))
    parser.add_argument("--output", metavar="URL", default=output_default,
                        help=f"{output_help} (default {output_default})")
    parser.add_argument("--duration", metavar="S", type=number(0, False, max_duration_s, "s"),
                        help=f"seconds of input, at most {max_duration_s:g} (default: the input's own duration)")
    add_drive_arguments(parser)


def add_drive_arguments(parser: argparse.ArgumentParser) -> None:
    """The device and drive options every real-time or offline session takes (``--device``, ``--rate``,
    ``--block``, the power budgets, ``--force``, ``--track``, ``--no-mode-compensation``): see
    :func:`session_options`."""
    parser.add_argument("--device", metavar="FILE", help="device file, or a shipped device's name such as SLG_0.4 (default: default, SLG_0.56)")
    parser.add_argument("--rate", metavar="HZ", type=whole(MAX_RATE_HZ, "Hz, the highest rate tpad-rt runs at"),
                        default=192000, help=f"sample rate, at most {MAX_RATE_HZ} Hz (default 192000)")
    parser.add_argument("--block", metavar="N", type=whole(MAX_BLOCK_FRAMES, "frames"), default=64,
                        help=f"samples per block, 1 to {MAX_BLOCK_FRAMES} (default 64)")
    parser.add_argument("--power-budget", metavar="W", type=number(0, False, MAX_POWER_W, "W"),
                        help=f"instantaneous power cap, at most {MAX_POWER_W:g} W "
                        "(default: the device's power_budget_w)")
    parser.add_argument("--power-avg", metavar="W", type=number(0, False, MAX_POWER_W, "W"),
                        help=f"average power budget over the window, at most {MAX_POWER_W:g} W (default: the cap)")
    parser.add_argument("--force", metavar="N", type=number(0, True, MAX_FORCE_N, "N"),
                        help=f"contact force (N, at most {MAX_FORCE_N:g}) for every finger sample, overriding the "
                        "input's")
    parser.add_argument("--track", action="store_true",
                        help="follow the plate's resonance as the contact force moves it (the device circuit's loaded "
                        "resonance at each force; through a serial amplifier that measures phase, locked onto the "
                        "plate's measured resonance)")
    parser.add_argument("--no-mode-compensation", dest="mode_compensation", action="store_false",
                        help="on a device with a mode shape, command the texture's amplitude at an antinode instead of "
                        "under the finger (the standing wave then shows)")


def session_options(args: argparse.Namespace) -> RenderOptions:
    """The RenderOptions of :func:`add_session_arguments`' options."""
    from tpad_rt.pipeline import RenderOptions

    return RenderOptions(power_budget_w=args.power_budget, power_avg_w=args.power_avg, track=args.track,
                         mode_compensation=args.mode_compensation,
                         **({} if args.force is None else {"default_force_n": args.force}))


def add_parser(subparsers: Subparsers) -> None:
    """Register ``render``."""
    parser = subparsers.add_parser(
        "render",
        help="render a texture offline into a recording (.npz) or a WAV file",
        description="Render TEXTURE for the finger path of --input, faster than real time, into --out "
        "(.npz: recording with telemetry and the simulated plate; .wav: the drive).",
    )
    add_session_arguments(parser)
    parser.add_argument("--out", metavar="FILE", required=True,
                        help=f"FILE.npz (recording, at most {MAX_RECORDING_SAMPLES:,} drive samples: "
                        f"{MAX_RECORDING_SAMPLES // 192000} s at 192 kHz) or FILE.wav (drive)")
    parser.set_defaults(func=run)


@dataclass
class Session:
    """An opened render: its loop, and the metadata the summary and the recording need."""

    render: OfflineRender
    metadata: dict[str, Any]


def open_session(args: argparse.Namespace, stack: contextlib.ExitStack, *, keep_drive: bool,
                 wav_path: Path | None = None) -> Session:
    """Load, open and wire everything ``args`` name; resources close with ``stack``.

    Raises ConfigError for a bad file, URL or value, an endless input without
    ``--duration``, or a render beyond the limits (module docstring; checked before
    the outputs open and the kernel warms up); BackendError when an output cannot open.
    """
    from tpad_rt.device import Device
    from tpad_rt.offline import OfflineRender, check_render_size, input_span_s
    from tpad_rt.outputs.wav import WavOutput
    from tpad_rt.pipeline import Pipeline
    from tpad_rt.texture import load_compiled

    device = Device.default() if args.device is None else Device.from_file(args.device)
    texture = load_compiled(args.texture)
    source = stack.enter_context(open_input(args.input, device=device))
    if source.live:
        raise ConfigError(f"input {args.input}: follows a live finger, which cannot be rendered offline; "
                          "use tpad-rt play, or a scripted:// or file:// input")
    input_s = input_span_s(source, args.duration)
    options = session_options(args)
    # The ramp down starts at the first control step after the stop and lasts ramp_ms:
    # one control interval plus the ramp, and a whole block more, end in silence.
    tail_s = options.ramp_ms * 1e-3 + (options.control_interval + args.block) / args.rate
    check_render_size(input_s, tail_s, args.rate, args.block, keep_drive,
                      writes_wav=wav_path is not None or _writes_file(args.output))
    pipeline = Pipeline(device, texture, fs_hz=args.rate, options=options)
    outputs = [stack.enter_context(open_output(args.output, device=device, fs_hz=args.rate))]
    if wav_path is not None:
        outputs.append(stack.enter_context(WavOutput(wav_path, args.rate)))
    render = OfflineRender(pipeline, source, outputs, block_frames=args.block, input_s=input_s,
                           tail_s=tail_s, force_n=args.force, keep_drive=keep_drive)
    metadata = run_metadata(pipeline, texture, texture_path=str(args.texture), block_frames=args.block,
                            input_url=args.input, output_url=args.output)
    return Session(render, metadata)


def _writes_file(url: str) -> bool:
    """Whether the output ``url`` writes the file it names (False for a bad URL: opening it says what is wrong)."""
    try:
        return output_kind(url)[1].can(Capability.WRITES_FILE)
    except ConfigError:
        return False


def run(args: argparse.Namespace) -> int:
    """Render (module docstring); 0 on success."""
    from tpad_rt.compiling import compile_notice, ensure_compiled

    out = Path(args.out)
    if out.suffix.lower() not in (".npz", ".wav"):
        raise ConfigError(f"--out: must end in .npz (recording) or .wav (drive), got '{args.out}'")
    check_writable_target(out, "recordings and WAV files")
    console = Console(soft_wrap=True, highlight=False, markup=False, emoji=False)
    with contextlib.ExitStack() as stack:
        with compile_notice():  # the first run compiles the kernels: say so at once
            session = open_session(args, stack, keep_drive=out.suffix.lower() == ".npz",
                                   wav_path=out if out.suffix.lower() == ".wav" else None)
            ensure_compiled()  # every argument checked: compile the whole plan if the cache lacks it
            session.render.warm_up()
        started = time.perf_counter()
        _run_with_progress(session.render, console)
        wall_s = time.perf_counter() - started
    result = session.render.result()
    judge_departures(result, session.metadata, session.render.pipeline.texture)
    if result.drive is not None:
        write_recording(out, Recording(result.fs_hz, result.drive, result.blocks, session.metadata))
    for line in summary_lines(result, session.metadata, wall_s, session.render.pipeline.texture):
        console.print(line)
    console.print(f"wrote {out}")
    return 0


def _run_with_progress(render: OfflineRender, console: Console) -> None:
    """Render every block, with a progress bar in audio seconds when ``console`` is a terminal."""
    seconds_per_block = render.block_frames / render.pipeline.fs_hz
    with Progress(TextColumn("rendering"), BarColumn(), TaskProgressColumn(),
                  TextColumn("{task.fields[audio]}"), TimeRemainingColumn(),
                  console=console, transient=True, disable=not console.is_terminal) as progress:
        task = progress.add_task("render", total=render.total_blocks, audio="")
        while not render.done:
            render.step()
            audio = f"{render.blocks_done * seconds_per_block:.2f} s of audio"
            progress.update(task, completed=render.blocks_done, total=render.total_blocks, audio=audio)


def _percent(mask: np.ndarray) -> str:
    return f"{100 * np.count_nonzero(mask) / max(len(mask), 1):.1f} %"


def _settled(t_s: np.ndarray, touching: np.ndarray, settle_s: float) -> np.ndarray:
    """True for blocks at least ``settle_s`` (s) after the touch they belong to began (ramp, velocity)."""
    touch_start_s = np.where(touching & ~np.r_[False, touching[:-1]], t_s, -np.inf)
    return t_s - np.maximum.accumulate(touch_start_s) >= settle_s


def judge_departures(result: RenderResult, metadata: dict[str, Any], texture: CompiledTexture) -> None:
    """On the simulated plate, add the ``departed`` block column (1 where a touching block's achieved friction
    is further than DEPARTURE_TOLERANCE_MU from the texture under the finger) and its tolerance to ``metadata``."""
    blocks = result.blocks
    if "achieved_mu" not in blocks:
        return
    judged = judge_blocks(blocks, result.finger, texture, block_s=result.block_frames / result.fs_hz,
                          mu_floor=metadata["render_options"]["mu_floor"])
    blocks["departed"] = judged.departed.astype(np.int8)
    metadata["departure_tolerance_mu"] = DEPARTURE_TOLERANCE_MU


def _departure_line(result: RenderResult, texture: CompiledTexture) -> str:
    """How many touching blocks departed from the texture under the finger, and the worst one."""
    from tpad_rt.offline import texture_under_finger

    blocks = result.blocks
    departed = blocks["departed"] != 0
    felt_mu, known = texture_under_finger(result, texture)
    touching = ((blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0) & known
    error = np.where(touching, np.abs(felt_mu - blocks["achieved_mu"]), 0.0)
    worst = int(np.argmax(error)) if len(error) else 0
    worst_text = f"worst {error[worst]:.3f} at {blocks['t'][worst]:.3f} s" if touching.any() else "no touching block"
    if not departed.any():
        return (f"departures: none; every touching block within {DEPARTURE_TOLERANCE_MU:g} of the texture under the "
                f"finger ({worst_text})")
    return (f"departures: {np.count_nonzero(departed)} of {np.count_nonzero(touching)} touching blocks "
            f"({_percent(departed[touching])}) further than {DEPARTURE_TOLERANCE_MU:g} from the texture under the "
            f"finger ({worst_text}); `tpad-rt plot` shades them")


def peak_text(peak_v: float, max_v: float, kick_blocks: int, outside_kicks_v: float, clamp: str = "") -> str:
    """The drive's peak ``peak_v`` (V) against ``max_v`` (V; from ``clamp``, e.g. an amplifier, when not the
    device file) for ``play``'s and ``render``'s summaries; when the
    shaper held the drive at a limit in ``kick_blocks`` blocks (FLAG_SHAPER_LIMIT: the kick that moves the plate's
    envelope as fast as the limits allow, at a touch-down or a steep step) and the drive outside them stayed below
    the peak, at ``outside_kicks_v`` (V), says that the peak is there and what it was outside them: a kick is by
    design, not saturation."""
    text = f"peak {peak_v:.2f} V of {max_v:g} V max" + (f" ({clamp}'s clamp)" if clamp else "")
    if not kick_blocks or outside_kicks_v >= peak_v:
        return text
    return (f"{text}, in the shaper's kicks ({kick_blocks} block{'s' if kick_blocks != 1 else ''} at the limit to "
            f"move the plate as fast as it allows), {outside_kicks_v:.2f} V outside them")


def over_cap_line(blocks: int, peak_w: float) -> str:
    """The summary line of ``play`` and ``render`` for ``blocks`` (> 0) blocks in which the plate held more than
    the power cap, ``peak_w`` (W) at most, as the kernel's model has it."""
    return (f"plate: over the power cap in {blocks} blocks (peak {peak_w:.3f} W as the kernel's plate model has it): "
            "a press took the vibration it held into a finger that damps more, and the drive braked it back "
            "(docs/kernel.md, \"A harder press\")")


def summary_lines(result: RenderResult, metadata: dict[str, Any], wall_s: float,
                  texture: CompiledTexture) -> list[str]:
    """The end-of-render summary: speed, peak volts, power vs budgets, saturation, friction error.

    The friction error compares the simulated plate's friction with the texture where
    the finger really was (not the kernel's extrapolated target), over blocks where
    the finger touched, had settled (start ramp, velocity window) and the drive was
    not saturated.
    """
    from tpad_rt.offline import texture_under_finger

    blocks = result.blocks
    flags = blocks["saturated"].astype(np.int64)
    touching = (flags & FLAG_WATCHDOG) == 0
    saturated = (flags & (FLAG_VOLTAGE | FLAG_POWER)) != 0
    kicks = (flags & FLAG_SHAPER_LIMIT) != 0
    avg_budget = metadata["power_avg_w"]
    speed = result.seconds / max(wall_s, 1e-9)
    lines = [
        f"rendered {result.seconds:.3f} s of audio in {wall_s:.3g} s ({speed:.1f}x real time), "
        f"{len(flags)} blocks of {result.block_frames} at {result.fs_hz} Hz",
        "drive: " + peak_text(blocks["voltage_v"].max(initial=0.0), metadata["max_voltage_v"], int(np.count_nonzero(kicks)),
                              blocks["voltage_v"][~kicks].max(initial=0.0)),
        f"power: mean {blocks['power_w'].mean():.3f} W, peak {blocks['power_w'].max(initial=0.0):.3f} W "
        f"(cap {metadata['power_budget_w']:g} W"
        + (f", average budget {avg_budget:g} W over {metadata['power_window_s']:g} s)" if avg_budget else ")"),
        f"saturated: {_percent(saturated)} of blocks (voltage {_percent((flags & FLAG_VOLTAGE) != 0)}, "
        f"power {_percent((flags & FLAG_POWER) != 0)}); finger touching in {_percent(touching)}",
    ]
    over_cap = blocks["plate_w"] > metadata["power_budget_w"] * (1 + MODEL_GUARD_FRACTION)  # as the kernel counts
    if over_cap.any():
        lines.append(over_cap_line(int(np.count_nonzero(over_cap)), float(blocks["plate_w"].max())))
    faults = (flags & FLAG_FAULT) != 0
    if faults.any():
        lines.append(f"faults: {_percent(faults)} of blocks ({np.count_nonzero(faults)}): the drive ramped to 0 there "
                     "(docs/kernel.md \"Faults\")")
    if "achieved_mu" in blocks:
        felt_target, known = texture_under_finger(result, texture)
        options = metadata["render_options"]
        settle_s = (options["ramp_ms"] + options["velocity_window_ms"] + 3 * options["smoothing_ms"]) * 1e-3
        compared = touching & ~saturated & known & _settled(blocks["t"], touching, settle_s)
        mu_floor = options["mu_floor"]
        error = np.abs(np.clip(felt_target, mu_floor, 1.0) - blocks["achieved_mu"])[compared]
        if len(error):
            lines.append(f"friction |texture under the finger - achieved| (simulated plate; touching, "
                         f"not saturated): mean {error.mean():.4f}, 95th percentile {np.percentile(error, 95):.4f}")
    if "departed" in blocks:
        lines.append(_departure_line(result, texture))
    return lines
