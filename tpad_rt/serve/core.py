"""What ``tpad-rt serve`` decides, apart from the network: whose finger it is, when a client's sample happened,
how fast a client may send, which texture files a client may name, and what telemetry looks like.

API map
-------
ClockMap()
    ``update(newest_t, now_s) -> offset_s``: a client's clock (s) onto the stream clock
FingerOwner(idle_s)
    ``free_for(client, now_s)``, ``claim(client, now_s) -> bool``, ``release(client)``, ``holder``,
    ``holder_at(now_s)``: one client's finger at a time
TokenBucket(rate_per_s, burst)
    ``take(amount, now_s) -> bool``: the rate limits
TextureLibrary(folders, parse=parse_inline)
    ``load(request) -> (CompiledTexture, label)``: a SetTexture's name, path or YAML, compiled;
    ProtocolError ``texture`` or ``forbidden_path``
parse_inline(text, base_dir, folders) -> (TextureFile | None, errors)
    an inline texture's text read (picklable both ways: the server runs it in a worker process)
TelemetryFeed(renderer)
    ``pump()`` (drain the renderer's telemetry), ``summary(since_t) -> dict`` (one ``telemetry`` message)
device_info(renderer) -> dict
friction_map_png(texture, device) -> bytes, colorbar_png() -> bytes
    the page's images

docs/serve.md is the contract these implement: the finger policy, the clock mapping,
the limits, the folders.
"""

from __future__ import annotations

import io
import math
import os
from collections import deque
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from tpad_rt.config import TextureFile, load_texture, parse_texture
from tpad_rt.config.messages import did_you_mean
from tpad_rt.device import Device
from tpad_rt.errors import ConfigError
from tpad_rt.json_text import json_safe
from tpad_rt.kernel.layout import FLAG_FAULT, FLAG_POWER, FLAG_VOLTAGE, FLAG_WATCHDOG
from tpad_rt.physics.friction import relative_friction
from tpad_rt.serve.protocol import ProtocolError, SetTexture
from tpad_rt.shipped import TEXTURES_DIR, texture_names
from tpad_rt.texture import CompiledTexture, compile_texture

if TYPE_CHECKING:
    from tpad_rt.engine import Renderer

#: A client clock may run this much slower than the stream's (s/s) before its samples drift late.
CLOCK_SKEW = 1e-4
#: A client's newest sample mapped this far (s) before its arrival means its clock jumped: map afresh.
RESYNC_S = 0.5
#: Telemetry rows the feed keeps for its subscribers (about 2 s at 192 kHz in blocks of 64).
FEED_ROWS = 8192
#: Most grid points of the page's friction map (the plate drawn as ``show`` draws it).
MAP_POINTS = 600 * 300


class ClockMap:
    """A client's clock onto the stream clock: ``offset_s`` is the smallest ``arrival - t`` seen (the message
    the network and the scheduler delayed least), allowed to grow by CLOCK_SKEW per second; a client clock
    that jumps back (its newest sample mapped more than RESYNC_S before it arrived) is mapped afresh."""

    def __init__(self) -> None:
        self.offset_s: float | None = None
        self._synced_s = 0.0

    def update(self, newest_t: float, now_s: float) -> float:
        """The offset (s) to add to the client's times, after a message whose newest sample is at
        ``newest_t`` (client clock) arrived at stream time ``now_s``."""
        now_s, newest_t = float(now_s), float(newest_t)  # Python floats: the renderer's clock is a numpy one
        arrival_offset_s = now_s - newest_t
        if self.offset_s is None or newest_t + self.offset_s < now_s - RESYNC_S:
            self.offset_s = arrival_offset_s
        else:
            self.offset_s = min(arrival_offset_s, self.offset_s + (now_s - self._synced_s) * CLOCK_SKEW)
        self._synced_s = now_s
        return self.offset_s


class FingerOwner:
    """Which client's finger the renderer follows: the first to send a sample holds it until it lifts,
    disconnects or sends nothing for ``idle_s`` (s); meanwhile the others' samples are refused."""

    def __init__(self, idle_s: float):
        self.idle_s = idle_s
        self.holder: object | None = None
        self._last_s = -math.inf

    def free_for(self, client: object, now_s: float) -> bool:
        """Whether ``client`` may push now: it holds the finger, or nobody does, or the holder is idle."""
        return self.holder is None or self.holder is client or now_s - self._last_s > self.idle_s

    def claim(self, client: object, now_s: float) -> bool:
        """Whether ``client`` holds the finger now (taking it when :meth:`free_for` it)."""
        if self.free_for(client, now_s):
            self.holder = client
            self._last_s = now_s
            return True
        return False

    def holder_at(self, now_s: float) -> object | None:
        """Who holds the finger at ``now_s``: None when nobody does or the holder is idle."""
        return None if self.holder is None or now_s - self._last_s > self.idle_s else self.holder

    def release(self, client: object) -> bool:
        """Free the finger if ``client`` holds it; whether it did."""
        if self.holder is client:
            self.holder = None
            return True
        return False


class TokenBucket:
    """``rate_per_s`` units a second on average, ``burst`` at once."""

    def __init__(self, rate_per_s: float, burst: float):
        self.rate_per_s, self.burst = rate_per_s, burst
        self._level = burst
        self._at_s = -math.inf

    def take(self, amount: float, now_s: float) -> bool:
        """Take ``amount`` units if there are that many; whether it could."""
        self._level = min(self.burst, self._level + (now_s - self._at_s) * self.rate_per_s)
        self._at_s = now_s
        if amount > self._level:
            return False
        self._level -= amount
        return True


#: How an inline texture's text is read: ``(text, base_dir, folders) -> (model | None, error lines)``.
InlineParse = Callable[[str, Path, list[Path]], "tuple[TextureFile | None, list[str]]"]


def parse_inline(text: str, base_dir: Path, folders: list[Path]) -> tuple[TextureFile | None, list[str]]:
    """The texture file whose text is ``text`` (relative images from ``base_dir``, every image within
    ``folders``): ``(model, [])``, or ``(None, its breadcrumb errors)``."""
    try:
        return parse_texture(text.encode(), "yaml", base_dir, folders), []
    except ConfigError as problem:
        return None, problem.errors


class TextureLibrary:
    """The textures clients may set: the shipped ones by name, files by path within the shipped textures' folder
    and ``folders`` (resolved, links followed), inline YAML whose images lie within them (relative image paths
    from the shipped folder)."""

    def __init__(self, folders: list[Path], parse: InlineParse = parse_inline):
        self.folders = list(dict.fromkeys(Path(os.path.realpath(folder)) for folder in [TEXTURES_DIR, *folders]))
        self._parse = parse

    def load(self, request: SetTexture) -> tuple[CompiledTexture, str]:
        """``(compiled texture, what it came from)``; ProtocolError ``texture`` (its breadcrumb errors, one per
        line) or ``forbidden_path`` (a path outside the folders)."""
        try:
            if request.name is not None:
                names = texture_names()
                if request.name not in names:
                    raise ProtocolError("texture", f"no shipped texture is called {request.name!r}"
                                        f"{did_you_mean(request.name, names)} (shipped: {', '.join(names)})",
                                        request.id, "texture")
                return compile_texture(load_texture(TEXTURES_DIR / f"{request.name}.yaml", self.folders)), request.name
            if request.path is not None:
                return compile_texture(load_texture(self._allowed(request), self.folders)), request.path
            assert request.yaml is not None
            model, errors = self._parse(request.yaml, self.folders[0], self.folders)
            if model is None:
                raise ConfigError(errors)
            return compile_texture(model), "inline YAML"
        except ConfigError as problem:
            raise ProtocolError("texture", str(problem), request.id, "texture") from None

    def _allowed(self, request: SetTexture) -> Path:
        """The file ``request.path`` names, if it lies in one of the folders; ProtocolError otherwise."""
        assert request.path is not None
        if "\0" in request.path:
            raise ProtocolError("forbidden_path", "the path contains a NUL byte", request.id, "texture")
        resolved = Path(os.path.realpath(request.path))
        if not any(resolved.is_relative_to(folder) for folder in self.folders):
            raise ProtocolError("forbidden_path", f"{request.path!r} lies outside the folders this server reads "
                                "textures from (" + ", ".join(str(folder) for folder in self.folders) + "; "
                                "tpad-rt serve --texture-dir adds one)", request.id, "texture")
        return resolved


class TelemetryFeed:
    """The renderer's telemetry rows of the last FEED_ROWS blocks, summarised per subscriber."""

    def __init__(self, renderer: Renderer):
        self._renderer = renderer
        self._chunks: deque[dict[str, np.ndarray]] = deque()
        self._rows = 0

    def pump(self) -> None:
        """Take the renderer's new rows (the feed is their only reader)."""
        rows = self._renderer.telemetry()
        if not len(rows["t"]):
            return
        self._chunks.append(rows)
        self._rows += len(rows["t"])
        while self._rows - len(self._chunks[0]["t"]) >= FEED_ROWS:
            self._rows -= len(self._chunks.popleft()["t"])

    def summary(self, since_t: float) -> dict[str, Any] | None:
        """A ``telemetry`` message of the blocks after stream time ``since_t`` (s): the newest block's finger,
        friction, amplitude, drive and power, the peaks over them, and which limits held; None if none."""
        fresh = [chunk for chunk in self._chunks if chunk["t"][-1] > since_t]
        if not fresh:
            return None
        rows = {name: np.concatenate([chunk[name] for chunk in fresh]) for name in fresh[0]}
        keep = rows["t"] > since_t
        rows = {name: column[keep] for name, column in rows.items()}
        flags = int(np.bitwise_or.reduce(rows["saturated"].astype(np.int64)))
        last = {name: float(column[-1]) for name, column in rows.items()}
        device = self._renderer.device
        touching = (int(last["saturated"]) & FLAG_WATCHDOG) == 0
        speed_m_s = max(last["speed_mm_s"] * 1e-3, device.speed_floor_m_s)
        achieved = float(relative_friction(last["amplitude_um"] * 1e-6, device.carrier_hz, speed_m_s, device.mu0,
                                           device.poisson, device.psi_star))
        return {
            "type": "telemetry", "t": last["t"], "blocks": int(len(rows["t"])), "touching": touching,
            "x_mm": last["x_mm"], "y_mm": last["y_mm"], "speed_mm_s": last["speed_mm_s"],
            "force_n": last["force_n"], "target_mu": last["target_mu"], "achieved_mu": achieved,
            "amplitude_um": last["amplitude_um"], "voltage_v": last["voltage_v"],
            "voltage_peak_v": float(rows["voltage_v"].max()), "power_w": last["power_w"],
            "power_peak_w": float(rows["power_w"].max()),
            "limited": {"voltage": bool(flags & FLAG_VOLTAGE), "power": bool(flags & FLAG_POWER),
                        "fault": bool(flags & FLAG_FAULT)},
        }


def device_info(renderer: Renderer) -> dict[str, Any]:
    """The ``device`` message: the plate (mm), the limits, the drive the run uses (the carrier, full scale and
    clamp: on ``serial://`` the amplifier's), the stream's rate and block, and the default force and watchdog
    the renderer applies."""
    device, options, stats, drive = renderer.device, renderer.options, renderer.stats(), renderer.drive
    plate = device.plate
    return {
        "type": "device", "label": device.label, "description": device.description,
        "plate": {"length_mm": plate.length_m * 1e3, "width_mm": plate.width_m * 1e3,
                  "thickness_mm": plate.thickness_m * 1e3, "material": plate.material, "mode": list(plate.mode)},
        "carrier_hz": drive.carrier_hz, "max_voltage_v": drive.max_voltage_v,
        "volts_per_full_scale": drive.volts_per_full_scale, "drive_source": drive.source,
        "power_budget_w": json_safe(stats["power_budget_w"]), "power_avg_w": json_safe(stats["power_avg_w"]),
        "default_force_n": options.default_force_n, "watchdog_ms": options.watchdog_ms,
        "rate_hz": renderer.rate_hz, "block_frames": renderer.block_frames, "output": renderer.output_url,
    }


def friction_map_png(texture: CompiledTexture, device: Device) -> bytes:
    """The target friction over the plate as ``tpad-rt show`` draws it (a finger at 100 mm/s towards +x,
    0.5 N, at t = 0; viridis from 0 to 1, row 0 at y = 0), one pixel per grid cell, as PNG bytes."""
    from matplotlib import colormaps

    from tpad_rt.plate_maps import Finger, plate_maps

    length_mm, width_mm = device.plate.length_m * 1e3, device.plate.width_m * 1e3
    resolution_mm = max(0.25, math.sqrt(length_mm * width_mm / MAP_POINTS))
    maps = plate_maps(texture, device, Finger(100.0, 0.0, 0.5), 0.0, resolution_mm)
    return _png(colormaps["viridis"](np.clip(maps.friction, 0.0, 1.0), bytes=True)[:, :, :3])


def _png(rgb: np.ndarray) -> bytes:
    """``rgb`` (uint8 ``[rows, columns, 3]``) as PNG bytes."""
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(out, format="PNG")
    return out.getvalue()


def colorbar_png() -> bytes:
    """The friction map's colour scale (viridis, 0 to 1 left to right), 256 x 1 pixels, as PNG bytes."""
    from matplotlib import colormaps

    return _png(colormaps["viridis"](np.linspace(0.0, 1.0, 256)[None, :], bytes=True)[:, :, :3])
