"""``tpad-rt show TEXTURE --out FILE.png``: a texture drawn over the plate, with what it costs to render.

Three maps over the device's plate (length x width, y down as on the screen), for a
finger sliding at ``--speed-mm-s`` towards ``--direction-deg`` with ``--force-n``
at ``--t-s`` seconds after the texture was set (at most ``tpad_rt.plate_maps.MAX_T_S``, 1e6 s:
past it a texture's phase in time loses its precision; a texture repeats with its period):

1. the target relative friction, evaluated by the compiled texture kernel;
2. the peak drive volts that friction asks for (inverse friction model at the finger
   speed, at least the device's speed floor, divided by the plate's amplitude per
   volt at that force and, on a device with a mode shape, by the share of it the
   finger's contact patch feels there), clipped at the device's ``max_voltage_v``;
   where it would exceed it, the area is hatched and outlined (saturated);
3. the estimated electrical power of the clipped drive, with a contour at the
   device's power budget;
4. on a device with a mode shape (its file's ``mode_shape``), the standing wave along
   the plate, its nodal lines, and the share of the antinode amplitude the contact
   patch feels at each x (what the drive above is divided by).

Prints one line: the file written and the share of the plate that saturates; and when the
friction map is flat but the texture changes in time (a temporal texture: the same
everywhere at one time), a second line saying so, with a ``--t-s`` that draws another
level (the friction panel's title says it too).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console

from tpad_rt.cli.arguments import Subparsers, decimal
from tpad_rt.errors import ConfigError, printable
from tpad_rt.figures import figure_target, pyplot, save

# The parser needs none of these (the maps come from the texture kernel): run imports them.
if TYPE_CHECKING:
    from tpad_rt.device import Device
    from tpad_rt.plate_maps import Finger, PlateMaps
    from tpad_rt.texture import CompiledTexture

_BUDGET_COLOUR = "#00c8ff"
#: Seconds of the texture's time sampled, 1 ms apart from ``--t-s``, to tell whether a flat map changes in time.
TIME_SPAN_S = 2.0


def add_parser(subparsers: Subparsers) -> None:
    """Register ``show``."""
    parser = subparsers.add_parser(
        "show",
        help="draw a texture over the plate: target friction, drive volts and power",
        description="Draw a texture's target friction over the device's plate, the drive volts it asks for "
        "at a finger speed and force (clipped at the device's maximum, saturated area hatched) and the "
        "estimated power against the device's power budget.",
    )
    parser.add_argument("texture", metavar="TEXTURE", help="texture file (.yaml)")
    parser.add_argument("--device", metavar="FILE", help="device file, or a shipped device's name such as SLG_0.4 (default: default, SLG_0.56)")
    parser.add_argument("--speed-mm-s", type=decimal, default=100.0, help="finger speed, mm/s (default 100)")
    parser.add_argument("--force-n", type=decimal, default=0.5, help="contact force, N (default 0.5)")
    parser.add_argument("--direction-deg", type=decimal, default=0.0,
                        help="direction of finger motion, degrees counter-clockwise from +x on screen (default 0)")
    parser.add_argument("--t-s", type=decimal, default=0.0, help="seconds since the texture was set (default 0)")
    parser.add_argument("--resolution-mm", type=decimal, default=0.25, help="grid step, mm (default 0.25)")
    parser.add_argument("--out", metavar="FILE.png", required=True, help="figure to write (.png, .pdf or .svg)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the figure and print a one-line summary; 0 on success.

    Raises ConfigError for a bad texture or device file, a bad option value or an
    ``--out`` that exists and is not a regular file, BackendError when the figure
    cannot be written.
    """
    from tpad_rt.device import Device
    from tpad_rt.plate_maps import Finger, plate_maps
    from tpad_rt.texture import load_compiled

    finger = Finger(
        speed_mm_s=_checked("--speed-mm-s", args.speed_mm_s, minimum=0.0),
        direction_deg=_checked("--direction-deg", args.direction_deg),
        force_n=_checked("--force-n", args.force_n, minimum=0.0),
    )
    t_s = _checked("--t-s", args.t_s, minimum=0.0)
    resolution_mm = _checked("--resolution-mm", args.resolution_mm, minimum=0.0, inclusive=False)
    out = figure_target("--out", args.out)
    device = Device.default() if args.device is None else Device.from_file(args.device)
    texture = load_compiled(args.texture)
    maps = plate_maps(texture, device, finger, t_s, resolution_mm)
    hint = time_hint(maps, texture, finger, t_s)
    figure = draw(maps, texture, device, finger, t_s, source=Path(args.texture).name, in_time=hint is not None)
    save(figure, out)
    _summary(out, maps, device)
    if hint is not None:
        print(hint)
    return 0


def time_hint(maps: PlateMaps, texture: CompiledTexture, finger: Finger, t_s: float) -> str | None:
    """When the friction map is flat but the texture changes in time at the plate's centre (over TIME_SPAN_S
    from ``t_s``): one line saying so, with the range and a ``--t-s`` (at most MAX_T_S) that draws another level,
    written with the fewest digits (4 at least) that stay within 1 ms of it and still draw that level; else None."""
    from tpad_rt.plate_maps import MAX_T_S

    level = float(maps.friction.flat[0])
    if not np.all(maps.friction == level):
        return None
    times_s = t_s + np.arange(0.0, TIME_SPAN_S, 1e-3)
    ux, uy = finger.unit_direction
    x_mm, y_mm = maps.x_mm[len(maps.x_mm) // 2], maps.y_mm[len(maps.y_mm) // 2]
    values = texture.evaluate(x_mm, y_mm, ux, uy, times_s)
    other = (np.abs(values - level) > 1e-9) & (times_s <= MAX_T_S)
    if not other.any():
        return None
    first = int(np.argmax(other))
    stretch = other[first:]
    middle = first + (len(stretch) if stretch.all() else int(np.argmin(stretch))) // 2  # of the first other stretch
    suggested = _shortest(times_s[middle], 4, lambda t: (np.abs(t - times_s[middle]) < 1e-3)
                          & (texture.evaluate(x_mm, y_mm, ux, uy, t) == values[middle]))
    return (f"the map is flat at t = {_seconds(t_s)} s ({level:.3g} everywhere): this texture changes in time, not "
            f"over the plate (friction {values.min():.3g} to {values.max():.3g} over {TIME_SPAN_S:g} s from there); "
            f"--t-s {suggested} draws it at {values[middle]:.3g}")


def _seconds(t_s: float) -> str:
    """``t_s`` (s) as the shortest decimal of 6 to 17 significant digits that reads back as it (``%g`` rounds a
    time such as 86401.022 to 86401)."""
    return _shortest(t_s, 6, lambda t: t == t_s)


def _shortest(value: float, fewest: int, keeps: Callable[[np.ndarray], np.ndarray]) -> str:
    """The shortest of ``value``'s ``%g`` decimals of ``fewest`` to 17 significant digits whose value ``keeps``
    accepts (it takes an array of them); the 17-digit one, which reads back as ``value``, when it accepts none."""
    texts = [f"{value:.{digits}g}" for digits in range(fewest, 18)]
    kept = keeps(np.array([float(text) for text in texts]))
    return texts[int(np.argmax(kept))] if kept.any() else texts[-1]


def _checked(option: str, value: float, minimum: float | None = None, inclusive: bool = True) -> float:
    """``value`` if finite and at least (not ``inclusive``: above) ``minimum``; else ConfigError naming ``option``."""
    below = minimum is not None and (value < minimum if inclusive else value <= minimum)
    if not math.isfinite(value) or below:
        bound = "" if minimum is None else f" {'>=' if inclusive else '>'} {minimum:g}"
        raise ConfigError(f"{option}: must be a finite number{bound}, got {value:g}")
    return value


def draw(maps: PlateMaps, texture: CompiledTexture, device: Device, finger: Finger, t_s: float, source: str,
         in_time: bool = False) -> Any:
    """A matplotlib Figure of the three maps (module docstring), titled with the texture's description;
    ``in_time``: the friction map is flat at ``t_s`` but the texture changes in time (its title says so)."""
    plt = pyplot()

    shaped = device.contact_width_m is not None
    figure, panels = plt.subplots(4 if shaped else 3, 1, figsize=(8.6, 13.4 if shaped else 11.0), layout="constrained",
                                  sharex=True, height_ratios=[1, 1, 1, 0.55] if shaped else None)
    # printable: a control character (a NUL in a description) has no glyph, and matplotlib warns about it
    figure.suptitle(printable(texture.description), fontsize=12, fontweight="bold")
    moving = f"towards {finger.direction_deg:g}°" if finger.speed_mm_s > 0 else "(still)"
    figure.supxlabel(f"{printable(source)} ({texture.kind}) on {printable(device.label)}: finger {finger.speed_mm_s:g} mm/s {moving}, "
                     f"{finger.force_n:g} N, t = {_seconds(t_s)} s", fontsize=9, color="0.3")
    extent = (0.0, device.plate.length_m * 1e3, device.plate.width_m * 1e3, 0.0)
    _friction_panel(figure, panels[0], maps, extent, t_s if in_time else None)
    if finger.speed_mm_s > 0:
        _direction_arrow(panels[0], finger.direction_deg)
    _volts_panel(figure, panels[1], maps, device, extent)
    _power_panel(figure, panels[2], maps, device, extent)
    if device.contact_width_m is not None:
        _mode_panel(figure, panels[3], device, device.contact_width_m * 1e3)
    panels[-1].set_xlabel("x (mm)")
    return figure


def _map(figure: Any, axes: Any, values: np.ndarray, extent: tuple[float, ...], cmap: str, vmax: float,
         label: str) -> Any:
    """Draw ``values`` over the plate on ``axes`` (y down, 0 to ``vmax``) with a colourbar; returns it."""
    image = axes.imshow(values, extent=extent, origin="upper", cmap=cmap, vmin=0.0, vmax=vmax,
                        interpolation="nearest", aspect="equal")
    axes.set_ylabel("y (mm)")
    return figure.colorbar(image, ax=axes, label=label, shrink=0.9, pad=0.02)


def _friction_panel(figure: Any, axes: Any, maps: PlateMaps, extent: tuple[float, ...],
                    changes_at_s: float | None) -> None:
    """The friction map; ``changes_at_s``: the time (s) of a flat map of a texture that changes in time."""
    _map(figure, axes, maps.friction, extent, "viridis", 1.0, "relative friction μ'")
    low, high = maps.friction.min(), maps.friction.max()
    levels = f"{low:.3g} everywhere" if low == high else f"{low:.3g} to {high:.3g}"
    if changes_at_s is not None:
        levels += f" at t = {_seconds(changes_at_s)} s; it changes in time (--t-s draws another)"
    axes.set_title(f"target friction (1: vibration off): {levels}", fontsize=10, loc="left")


def _direction_arrow(axes: Any, direction_deg: float) -> None:
    """A 28-point arrow near the top-right corner of ``axes`` pointing where the finger moves (screen angle)."""
    from matplotlib import patheffects
    from matplotlib.text import OffsetFrom

    angle = math.radians(direction_deg)
    half = (14.0 * math.cos(angle), 14.0 * math.sin(angle))  # points, y up on the screen
    centre = OffsetFrom(axes, (0.93, 0.78), unit="points")
    outline = [patheffects.withStroke(linewidth=3.5, foreground="black")]
    axes.annotate("", xy=half, xycoords=centre, xytext=(-half[0], -half[1]), textcoords=centre,
                  arrowprops={"arrowstyle": "-|>", "color": "white", "lw": 2.0, "path_effects": outline})
    axes.annotate("finger", xy=(0.0, -18.0), xycoords=centre, ha="center", va="top", color="white", fontsize=8,
                  path_effects=outline)


def _volts_panel(figure: Any, axes: Any, maps: PlateMaps, device: Device, extent: tuple[float, ...]) -> None:
    _map(figure, axes, maps.volts, extent, "magma", device.max_voltage_v, "drive (V peak)")
    if maps.saturated.any():
        axes.contourf(maps.x_mm, maps.y_mm, maps.saturated.astype(float), levels=[0.5, 1.5], colors="none",
                      hatches=["////"])
        axes.contour(maps.x_mm, maps.y_mm, maps.saturated.astype(float), levels=[0.5], colors="#00c853",
                     linewidths=1.0)
    axes.set_title(f"drive asked for, clipped at {device.max_voltage_v:g} V; hatched: saturated, "
                   f"{maps.saturated_percent:.1f} % of the plate (asks up to {maps.volts_asked.max():.3g} V)",
                   fontsize=10, loc="left")


def _power_panel(figure: Any, axes: Any, maps: PlateMaps, device: Device, extent: tuple[float, ...]) -> None:
    budget_w = device.power_budget_w
    top_w = max(float(maps.power_w.max()), budget_w) * 1.05
    colourbar = _map(figure, axes, maps.power_w, extent, "inferno", top_w, "estimated power (W)")
    colourbar.ax.axhline(budget_w, color=_BUDGET_COLOUR, linewidth=2.0)
    over = maps.power_w > budget_w
    if over.any():
        axes.contour(maps.x_mm, maps.y_mm, maps.power_w, levels=[budget_w], colors=_BUDGET_COLOUR, linewidths=1.2)
        state = f"over it on {100.0 * over.mean():.1f} % of the plate"
    else:
        state = "not reached"
    axes.set_title(f"estimated power, peak {maps.power_w.max():.3g} W; budget {budget_w:g} W (cyan): {state}",
                   fontsize=10, loc="left")


def _mode_panel(figure: Any, axes: Any, device: Device, contact_width_mm: float) -> None:
    """The standing wave along the plate, its nodal lines, and the share of the antinode amplitude a
    ``contact_width_mm`` patch feels; as wide as the maps above (an empty colourbar's room kept)."""
    from matplotlib.cm import ScalarMappable

    figure.colorbar(ScalarMappable(), ax=axes, shrink=0.9, pad=0.02).ax.set_visible(False)
    length_mm = device.plate.length_m * 1e3
    x_mm = np.linspace(0.0, length_mm, 4001)
    wave = device.mode_deflection(x_mm)
    felt = device.mode_gain(x_mm)
    nodes_mm = x_mm[:-1][np.sign(wave[1:]) != np.sign(wave[:-1])]
    axes.plot(x_mm, wave, color="0.6", linewidth=0.8, label="standing wave (antinode = 1)")
    axes.plot(x_mm, felt, color="#d81b60", linewidth=1.8, label="felt over the contact patch")
    for node_mm in nodes_mm:
        axes.axvline(node_mm, color="0.8", linewidth=0.6, linestyle=":")
    axes.axhline(0.0, color="0.5", linewidth=0.5)
    axes.set_xlim(0.0, length_mm)
    axes.set_ylabel("amplitude / antinode")
    axes.legend(loc="lower right", fontsize=7, framealpha=0.9)
    middle = (x_mm > 0.1 * length_mm) & (x_mm < 0.9 * length_mm)
    spacing_mm = float(np.median(np.diff(nodes_mm))) if len(nodes_mm) > 1 else length_mm
    axes.set_title(f"{device.plate.mode[0]} x {device.plate.mode[1]} mode, nodal lines {spacing_mm:.2g} mm apart: a "
                   f"{contact_width_mm:g} mm contact patch feels {felt[middle].min():.2f} to {felt[middle].max():.2f} "
                   "of the antinode amplitude", fontsize=10, loc="left")


def _summary(out: Path, maps: PlateMaps, device: Device) -> None:
    """One line on stdout: the file written and the saturated share of the plate."""
    console = Console(soft_wrap=True, highlight=False, markup=False, emoji=False)
    console.print(f"wrote {out}: {maps.saturated_percent:.1f} % of the plate saturated "
                  f"(drive > {device.max_voltage_v:g} V), peak power {maps.power_w.max():.3g} W "
                  f"of a {device.power_budget_w:g} W budget")
