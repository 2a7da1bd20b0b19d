"""``tpad-rt plot FILE.npz --out FILE.png``: a recording as a figure.

Four panels against time (or, with ``--along x``, the finger's x; when x turns back, as on a
circle or a back-and-forth swipe, the distance along the finger's path instead, with a note,
since x would fold the path onto itself; refused when the finger touches in no block): relative friction
(target, and achieved when the plate was simulated), plate amplitude (commanded, and
simulated), drive volts against the device maximum, and power against the cap and the
average budget (the drive's per block, and averaged over the budget's window; the
plate's, as the kernel's model has it, where a press took it over the cap). Blocks where
the drive saturated are shaded red, blocks without a touching finger grey; on the
friction panel, blocks whose achieved friction departed from the texture under the
finger by more than the recording's tolerance (``departed``, from ``tpad-rt render``
on the simulated plate) are shaded in purple in a strip along the panel's foot, below the curves.
"""

from __future__ import annotations

import argparse
import math
import zipfile
from typing import Any

import numpy as np

from tpad_rt.cli.arguments import Subparsers, decimal
from tpad_rt.errors import ConfigError, printable
from tpad_rt.figures import figure_target, pyplot, save
from tpad_rt.files import ensure_regular
from tpad_rt.kernel.layout import FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG, MODEL_GUARD_FRACTION
from tpad_rt.recording import Recording, read_recording

#: What plot says of an amplifier emulator's recording (``tpad-rt amp emulate --record``).
AMPLIFIER_RECORDING = (
    "an amplifier emulator's recording (tpad-rt amp emulate --record): plot draws the recordings of render and of "
    "play --record (play --output serial://PORT --record FILE.npz records the same run on the host's side); "
    "docs/amplifiers.md, 'Checking a recording', shows how to check this one")
#: Entries every amplifier emulator's recording holds (tpad_rt.amp.emulator.RECORDED_COLUMNS), as archive members.
_AMPLIFIER_ENTRIES = {"t_s.npy", "envelope_v.npy", "index.npy", "plate_amplitude_um.npy"}

_TARGET, _ACHIEVED, _LIMIT, _AVERAGE = "#1f5fa8", "#e07b00", "#c0392b", "#6a3d9a"
_SATURATED, _LIFTED, _DEPARTED = "#e74c3c", "#7f8c8d", "#8e44ad"
#: Height of the departures' strip, a fraction of the friction panel's (the y limits keep the curves above it).
DEPARTED_STRIP = 0.06


def add_parser(subparsers: Subparsers) -> None:
    """Register ``plot``."""
    parser = subparsers.add_parser(
        "plot",
        help="plot a recording: friction, amplitude, volts and power",
        description="Plot a recording made by 'tpad-rt render --out FILE.npz' (or 'play --record').",
    )
    parser.add_argument("recording", metavar="FILE.npz", help="recording to plot")
    parser.add_argument("--out", metavar="FILE", required=True, help="image to write (.png, .pdf or .svg)")
    parser.add_argument("--along", choices=("time", "x"), default="time",
                        help="horizontal axis: time (default) or the finger's x position")
    parser.add_argument("--start", metavar="S", type=decimal, default=-math.inf, help="plot from this time (s)")
    parser.add_argument("--end", metavar="S", type=decimal, default=math.inf, help="plot up to this time (s)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Plot the recording; 0 on success. ConfigError for a bad, missing or non-regular recording, or an
    image name that is not a figure or names an existing non-regular file."""
    out = figure_target("--out", args.out)
    ensure_regular(args.recording, "recordings")
    if _amplifier_recording(args.recording):
        raise ConfigError(f"{args.recording}: {AMPLIFIER_RECORDING}")
    figure, note = plot_recording(read_recording(args.recording), along=args.along, start_s=args.start,
                                  end_s=args.end)
    save(figure, out)
    print(f"wrote {out}" + (f" ({note})" if note else ""))
    return 0


def _amplifier_recording(path: str) -> bool:
    """True when ``path`` is an archive holding an amplifier emulator's recording, not a tpad-rt recording; False
    for anything else (read_recording then says what it is)."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        return False
    return _AMPLIFIER_ENTRIES <= names and "format.npy" not in names


def plot_recording(recording: Recording, along: str = "time", start_s: float = -math.inf,
                   end_s: float = math.inf) -> tuple[Any, str | None]:
    """A matplotlib Figure of ``recording``'s blocks from ``start_s`` to ``end_s`` (s) (module docstring), and a
    note when the horizontal axis is not the one asked for.

    ``along`` is ``time`` or ``x``. Raises ConfigError when no block lies in the span, or (``x``) when the finger
    touches in none of them.
    """
    plt = pyplot()
    from matplotlib.patches import Patch

    meta = recording.metadata
    if not len(recording.blocks["t"]):
        raise ConfigError("the recording holds no blocks: nothing to plot")
    for name, values in recording.blocks.items():
        if not np.isfinite(values).all():
            raise ConfigError(f"{name}: the recording holds NaN or infinite values; cannot plot them")
    inside = (recording.blocks["t"] >= start_s) & (recording.blocks["t"] <= end_s)
    if not inside.any():
        raise ConfigError(f"--start/--end: no block between {start_s:g} s and {end_s:g} s "
                          f"(the recording spans {recording.blocks['t'][0]:g} to {recording.blocks['t'][-1]:g} s)")
    power_average = _trailing_mean(recording.blocks["power_w"],
                                   meta["power_window_s"] * recording.fs_hz / meta["block_frames"])[inside]
    blocks = {name: values[inside] for name, values in recording.blocks.items()}
    flags = blocks["saturated"].astype(np.int64)
    touching = (flags & FLAG_WATCHDOG) == 0
    saturated = (flags & (FLAG_VOLTAGE | FLAG_POWER)) != 0
    note = None
    if along == "x" and not touching.any():
        raise ConfigError("--along x: the finger touches in no block" + ("" if inside.all() else " of that span")
                          + ": there is no x to plot along (plot along time, the default)")
    if along == "x" and _turns_back(blocks["x_mm"][touching]):
        note = "x turns back, which would fold the path onto itself: plotted along the finger's path instead"
        axis = np.where(touching, _path_mm(blocks["x_mm"], blocks["y_mm"], touching), np.nan)
        label = "distance along the finger's path (mm); not x, which turns back"
    elif along == "x":
        axis, label = np.where(touching, blocks["x_mm"], np.nan), "finger x (mm)"  # no lines to a lifted finger
    else:
        axis, label = blocks["t"], "time (s)"

    figure, panels = plt.subplots(4, 1, sharex=True, figsize=(11, 9.5), layout="constrained")
    friction, amplitude, volts, power = panels
    felt = {name: np.where(touching, blocks[name], np.nan)  # no finger, no friction (or command) to show
            for name in ("target_mu", "achieved_mu", "amplitude_um") if name in blocks}
    friction.plot(axis, felt["target_mu"], color=_TARGET, lw=1.4, label="target")
    amplitude.plot(axis, felt["amplitude_um"], color=_TARGET, lw=1.4, label="commanded")
    if recording.has_sim:
        friction.plot(axis, felt["achieved_mu"], color=_ACHIEVED, lw=1.2, label="achieved (simulated plate)")
        amplitude.plot(axis, blocks["plate_amplitude_um"], color=_ACHIEVED, lw=1.2, label="simulated plate")
    lowest = min(np.nanmin(values, initial=1.0) for name, values in felt.items() if name != "amplitude_um")
    friction.set(ylabel="relative friction μ'", ylim=(max(0.0, math.floor(10 * lowest - 1) / 10), 1.04))
    departed = blocks["departed"] != 0 if "departed" in blocks else np.zeros(len(axis), dtype=bool)
    if departed.any():  # a strip along the panel's foot: marks on the curve hid it where it departs
        tolerance = meta.get("departure_tolerance_mu", math.nan)
        _shade(friction, axis, departed, _DEPARTED, 0.55, top=DEPARTED_STRIP)
        departures = [Patch(color=_DEPARTED, alpha=0.55, label=f"departed > {tolerance:g} from the texture under the "
                            f"finger ({np.count_nonzero(departed)} blocks; the strip at the foot)")]
    else:
        departures = []
    amplitude.set(ylabel="amplitude (µm)")

    volts.plot(axis, blocks["voltage_v"], color=_TARGET, lw=1.2, label="drive (peak per block)")
    volts.axhline(meta["max_voltage_v"], color=_LIMIT, ls="--", lw=1.2, label=f"max {meta['max_voltage_v']:g} V")
    volts.set(ylabel="drive (V peak)", ylim=(0, meta["max_voltage_v"] * 1.12))

    power.plot(axis, blocks["power_w"], color=_TARGET, lw=0.8, alpha=0.8, label="drive (per block)")
    power.plot(axis, power_average, color=_AVERAGE, lw=1.6, label=f"average over {meta['power_window_s']:g} s")
    plate_w = blocks.get("plate_w", np.zeros(0))  # absent from recordings made before it was added
    over = plate_w > meta["power_budget_w"] * (1 + MODEL_GUARD_FRACTION)  # as the kernel counts them
    if over.any():  # a press took the plate's vibration over the cap: show the excursion and its braking
        power.plot(axis, np.where(over, plate_w, np.nan), color=_ACHIEVED, lw=1.4,
                   label=f"plate over the cap by more than {MODEL_GUARD_FRACTION:.0%}, as the model has it "
                         f"({np.count_nonzero(over)} blocks)")
    cap_w, average_w = meta["power_budget_w"], meta["power_avg_w"]
    if average_w == cap_w:
        power.axhline(cap_w, color=_LIMIT, ls="--", lw=1.2, label=f"cap and average budget {cap_w:g} W")
    else:
        power.axhline(cap_w, color=_LIMIT, ls="--", lw=1.2, label=f"cap {cap_w:g} W")
        power.axhline(average_w, color=_AVERAGE, ls=":", lw=1.4, label=f"average budget {average_w:g} W")
    power.set(ylabel="power (W)", xlabel=label,
              ylim=(0, max(cap_w, blocks["power_w"].max(), plate_w.max(initial=0.0)) * 1.15))

    shading = [Patch(color=_SATURATED, alpha=0.3, label="saturated"),
               Patch(color=_LIFTED, alpha=0.25, label="finger lifted")]
    for panel in panels:
        _shade(panel, axis, saturated, _SATURATED, 0.14)
        _shade(panel, axis, ~touching, _LIFTED, 0.10)
        panel.grid(True, color="#dddddd", lw=0.6)
        panel.spines[["top", "right"]].set_visible(False)
        handles, _ = panel.get_legend_handles_labels()
        panel.legend(handles=handles + (departures + shading if panel is friction else []),
                     loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    # printable: a control character (a NUL in a description) has no glyph, and matplotlib warns about it
    figure.suptitle(printable(f"{meta['texture_description']}  ·  {meta['device_label']}  ·  "
                              f"{meta.get('input_url', '')}"), fontsize=11)
    return figure, note


def _turns_back(x_mm: np.ndarray) -> bool:
    """True when ``x_mm`` both rises and falls by more than a micrometre from one block to the next."""
    steps = np.diff(x_mm)
    return bool((steps > 1e-3).any() and (steps < -1e-3).any())


def _path_mm(x_mm: np.ndarray, y_mm: np.ndarray, touching: np.ndarray) -> np.ndarray:
    """Distance (mm) along the finger's path at each block, counted between consecutive touching blocks only (a
    lift and a touch elsewhere is no path)."""
    steps = np.hypot(np.diff(x_mm), np.diff(y_mm)) * (touching[1:] & touching[:-1])
    return np.concatenate([[0.0], np.cumsum(steps)])


def _trailing_mean(values: np.ndarray, window_blocks: float) -> np.ndarray:
    """Mean of each block and the ones before it over ``window_blocks`` (fewer at the start)."""
    width = max(int(round(min(window_blocks, len(values)))), 1)  # a window past the end: every block
    sums = np.cumsum(np.concatenate([[0.0], values]))
    index = np.arange(1, len(values) + 1)
    start = np.maximum(index - width, 0)
    return (sums[index] - sums[start]) / (index - start)


def _shade(panel: Any, axis: np.ndarray, mask: np.ndarray, color: str, alpha: float, top: float = 1.0) -> None:
    """Shade the panel where ``mask`` holds, from its foot up to ``top`` (a fraction of its height)."""
    if mask.any():
        panel.fill_between(axis, 0, top, where=mask, color=color, alpha=alpha, lw=0,
                           transform=panel.get_xaxis_transform(), step="post")
