"""``tpad-rt serve [TEXTURE]``: one renderer for apps in any language, over WebSocket and OSC, with a page.

The process owns a :class:`~tpad_rt.engine.Renderer` on ``--output`` (``auto`` as for
``play``: an audio device, else ``sim://``) and serves, on ``--host``/``--port``, the
JSON WebSocket API at ``/ws``, the page at ``/`` (the plate with the texture's friction
map, the finger, target and achieved friction, drive and power, live; pointer and touch
on the plate are the finger), and OSC over UDP on loopback at ``--osc-port``
(:mod:`tpad_rt.serve`, docs/serve.md). The first line says where, once listening.

It listens on loopback unless ``--allow-remote``; then every WebSocket client must show
the token (``--token``, or one made up and printed). Ctrl-C (or SIGTERM, or
``--duration``) closes the connections, lifts the finger and ramps the drive to 0 as
``play`` does; a summary follows, and ``--record`` writes the run's recording. Errors
(a bad flag or file, a port in use, a lost output) end with one line and exit status 1.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import errno
import ipaddress
import os
import secrets
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console

from tpad_rt.cli.arguments import Subparsers, number, whole
from tpad_rt.cli.play import choose_output
from tpad_rt.cli.render import add_drive_arguments, session_options
from tpad_rt.errors import BackendError, ConfigError, printable
from tpad_rt.files import check_writable_target
from tpad_rt.limits import MAX_INPUT_S, MAX_STALL_TIMEOUT_S
from tpad_rt.shipped import TEXTURES_DIR, texture_file

if TYPE_CHECKING:
    import asyncio

    from tpad_rt.engine import Renderer
    from tpad_rt.serve.server import Server, Settings

#: The span (ms) the finger's velocity is estimated over: a 60 Hz client's samples are 16.7 ms apart, and the
#: estimate needs two within it (RenderOptions' 10 ms default suits play's inputs, about 1 kHz).
VELOCITY_WINDOW_MS = 40.0
#: Token length bounds (characters) and the characters a token may hold (URL-safe, no escaping needed).
MIN_TOKEN_CHARS, MAX_TOKEN_CHARS = 8, 256
_TOKEN_CHARS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_.~")


def add_parser(subparsers: Subparsers) -> None:
    """Register ``serve``."""
    parser = subparsers.add_parser(
        "serve",
        help="serve a renderer to apps (WebSocket JSON, OSC) with a live browser page",
        description="Render on --output for the finger of network clients: a JSON WebSocket API at "
        "ws://HOST:PORT/ws, a page at http://HOST:PORT/ showing the plate live (and taking pointer and touch as the "
        "finger), and OSC over UDP on loopback. docs/serve.md is the protocol. Ctrl-C stops with a ramp.",
    )
    parser.add_argument("texture", metavar="TEXTURE", nargs="?",
                        help="texture to start with, a file or a shipped name (default: none, the drive stays silent "
                        "until a client sets one)")
    parser.add_argument("--output", metavar="URL", default="auto",
                        help="output URL (audio://[device]?..., serial://PORT, sim://, null://), or auto: an audio "
                        "device that accepts --rate (JACK first), else sim:// (default auto)")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (default 127.0.0.1; another than loopback needs --allow-remote)")
    parser.add_argument("--port", type=whole(65535, "a TCP port; 0 picks a free one", low=0), default=8765,
                        help="TCP port of the page and the WebSocket (default 8765; 0: any free port)")
    parser.add_argument("--osc-port", type=whole(65535, "a UDP port; 0 picks a free one", low=0), default=8766,
                        help="UDP port for OSC, on loopback (default 8766; 0: any free port)")
    parser.add_argument("--no-osc", action="store_true", help="no OSC")
    parser.add_argument("--allow-remote", action="store_true",
                        help="let --host be an address other machines reach; WebSocket clients must then show the "
                        "token")
    parser.add_argument("--token", help=f"the token clients show (ws://HOST:PORT/ws?token=..., or 'Authorization: "
                        f"Bearer ...'), {MIN_TOKEN_CHARS}-{MAX_TOKEN_CHARS} URL-safe characters (default with "
                        "--allow-remote: a random one, printed)")
    parser.add_argument("--allow-origin", metavar="ORIGIN", action="append", default=[],
                        help="a web page origin (e.g. http://localhost:3000) whose scripts may open the WebSocket, "
                        "besides this server's own page; repeatable")
    parser.add_argument("--texture-dir", metavar="DIR", action="append", default=[],
                        help="a folder clients may name texture files (and images) in, besides the shipped textures "
                        "and TEXTURE's folder; repeatable")
    parser.add_argument("--duration", metavar="S", type=number(0, False, MAX_INPUT_S, "s"),
                        help=f"stop after S seconds, at most {MAX_INPUT_S:g} (default: until Ctrl-C)")
    parser.add_argument("--record", metavar="FILE.npz", help="also write a recording of the run (the format of render)")
    parser.add_argument("--stall-timeout", metavar="S", type=number(0, False, MAX_STALL_TIMEOUT_S, "s"), default=0.5,
                        help="an audio stream without a callback for S seconds has stalled (default 0.5)")
    parser.add_argument("--velocity-window-ms", metavar="MS", type=number(0, False, 1000.0, "ms"),
                        default=VELOCITY_WINDOW_MS,
                        help="span the finger's velocity is estimated over (default "
                        f"{VELOCITY_WINDOW_MS:g}: network clients send at display rates, 60-120 samples a second; "
                        "play's inputs send about 1000)")
    add_drive_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve (module docstring); 0 when it ends by Ctrl-C, SIGTERM or --duration."""
    import asyncio

    from tpad_rt.compiling import compile_notice
    from tpad_rt.device import Device
    from tpad_rt.serve.server import Server
    from tpad_rt.texture import load_compiled

    settings = _settings(args)
    if args.record is not None:
        if Path(args.record).suffix.lower() != ".npz":
            raise ConfigError(f"--record: must end in .npz, got '{args.record}'")
        check_writable_target(args.record, "recordings")
    console = Console(soft_wrap=True, highlight=False, markup=False, emoji=False)
    device = Device.default() if args.device is None else Device.from_file(args.device)
    texture = load_compiled(args.texture) if args.texture is not None else None
    output = choose_output(args.output, args.rate)
    with compile_notice():
        from tpad_rt.engine import Renderer

        options = dataclasses.replace(session_options(args), velocity_window_ms=args.velocity_window_ms)
        renderer = Renderer(device, output.url, texture=texture, rate_hz=args.rate, block_frames=args.block,
                            options=options, stall_timeout_s=args.stall_timeout)
        if args.record is not None:
            renderer.record(args.record)
        renderer.start()
    with renderer:
        server = Server(renderer, settings, None if args.texture is None else printable(args.texture))
        stopped_by = asyncio.run(_serve(server, settings, args.duration, console, str(output)))
    for line in _summary(server, renderer, stopped_by):
        console.print(line)
    if args.record is not None:
        console.print(f"wrote {args.record}")
    return 0


def _settings(args: argparse.Namespace) -> Settings:
    """The server's Settings from the flags; ConfigError for a host beyond loopback without --allow-remote,
    a bad token, or a texture folder that is not one."""
    from tpad_rt.serve.server import Settings

    if not (_loopback(args.host) or args.allow_remote):
        raise ConfigError(f"--host {args.host}: listens beyond this machine; add --allow-remote (clients then need "
                          "the token) or listen on 127.0.0.1")
    token = args.token
    if token is not None and not (MIN_TOKEN_CHARS <= len(token) <= MAX_TOKEN_CHARS and set(token) <= _TOKEN_CHARS):
        raise ConfigError(f"--token: must be {MIN_TOKEN_CHARS}-{MAX_TOKEN_CHARS} characters of A-Z a-z 0-9 - _ . ~")
    if token is None and args.allow_remote:
        token = secrets.token_urlsafe(18)
    folders = [TEXTURES_DIR]
    if args.texture is not None:
        reference = texture_file(args.texture)
        folders.append(Path(reference).parent)
    for folder in args.texture_dir:
        if not os.path.isdir(folder):
            raise ConfigError(f"--texture-dir {printable(folder)}: not a folder")
        folders.append(Path(folder))
    for origin in args.allow_origin:
        if not origin.startswith(("http://", "https://")) or origin.count("/") != 2:
            raise ConfigError(f"--allow-origin {printable(origin)}: an origin is scheme://host[:port], e.g. "
                              "http://localhost:3000")
    return Settings(host=args.host, port=args.port, osc_port=None if args.no_osc else args.osc_port, token=token,
                    allowed_origins=tuple(args.allow_origin), texture_dirs=tuple(folders))


def _loopback(host: str) -> bool:
    """Whether ``host`` names this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


async def _serve(server: Server, settings: Settings, duration_s: float | None, console: Console,
                 output: str) -> str:
    """Run ``server`` until Ctrl-C, SIGTERM or ``duration_s``; what stopped it. BackendError when it cannot
    listen; the renderer's error when it fails."""
    import asyncio

    stop, ready = asyncio.Event(), asyncio.Event()
    reasons: list[str] = []
    loop = asyncio.get_running_loop()
    with _stop_signals(loop, stop, reasons):
        if duration_s is not None:
            loop.call_later(duration_s, _stopper(stop, reasons, "--duration"))
        task = asyncio.create_task(server.run(stop, ready))
        waiting = asyncio.create_task(ready.wait())
        await asyncio.wait([task, waiting], return_when=asyncio.FIRST_COMPLETED)
        waiting.cancel()
        if task.done():
            _raise_listen_error(task, settings)
        host = f"[{settings.host}]" if ":" in settings.host else settings.host
        where = f"serving http://{host}:{server.port}/ (WebSocket ws://{host}:{server.port}/ws" + (
            f", OSC udp://127.0.0.1:{server.osc_port}" if server.osc_port is not None else "") + ")"
        console.print(f"{where}; output {output}; Ctrl-C stops")
        if settings.token is not None:
            console.print(f"token: {settings.token} (the page: http://{host}:{server.port}/?token={settings.token})")
        await task
    return reasons[0] if reasons else "the renderer"


def _raise_listen_error(task: asyncio.Task[None], settings: Settings) -> None:
    """Re-raise a server that ended before listening: an OSError binding a port as a BackendError."""
    error = task.exception()
    if isinstance(error, OSError):
        why = os.strerror(error.errno) if error.errno else str(error)
        hint = " (another tpad-rt serve? --port or --osc-port picks another)" if error.errno == errno.EADDRINUSE else ""
        raise BackendError(f"cannot listen on {settings.host} port {settings.port} or OSC port {settings.osc_port}: "
                           f"{why}{hint}") from None
    task.result()


def _stopper(stop: asyncio.Event, reasons: list[str], reason: str) -> Callable[[], None]:
    """A callback that notes ``reason`` and sets ``stop``."""
    def stopper() -> None:
        reasons.append(reason)
        stop.set()

    return stopper


@contextlib.contextmanager
def _stop_signals(loop: asyncio.AbstractEventLoop, stop: asyncio.Event, reasons: list[str]) -> Iterator[None]:
    """SIGINT (Ctrl-C) and SIGTERM set ``stop`` (noting which) while open."""
    names = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM"}
    for number_, name in names.items():
        loop.add_signal_handler(number_, _stopper(stop, reasons, name))
    try:
        yield
    finally:
        for number_ in names:
            loop.remove_signal_handler(number_)


def _count(number: int, noun: str) -> str:
    """``1 message``, ``2 messages``: ``number`` and ``noun``, plural unless it is 1."""
    return f"{number} {noun}" if number == 1 else f"{number} {noun}s"


def _summary(server: Server, renderer: Renderer, stopped_by: str) -> list[str]:
    """The end-of-serve summary: what the clients did and what the drive did."""
    counts, stats = server.counters, renderer.stats()
    errors = sum(value for key, value in counts.items() if key.startswith("error_"))
    refused = {key.removeprefix("refused_"): value for key, value in sorted(counts.items())
               if key.startswith("refused_") and value}
    lines = [
        f"served until {stopped_by}: {_count(counts['connections'], 'WebSocket connection')}, "
        f"{_count(counts['messages'], 'message')}, {_count(counts['osc_messages'], 'OSC message')}; "
        f"{_count(counts['samples'], 'finger sample')}, {_count(counts['textures_set'], 'texture')} set; "
        f"{errors} refused with an error, {counts['rate_limited']} dropped by the rate limits",
        f"HTTP: {_count(counts['http_requests'], 'request')}, {sum(refused.values())} refused"
        + (" (" + ", ".join(f"{count} {why}" for why, count in refused.items()) + ")" if refused else ""),
        f"played {stats['played_s']:.2f} s of drive: {stats['underflows']} underflows; push-to-output latency p50 "
        f"{stats['latency_ms_p50']:.2f} ms, p99 {stats['latency_ms_p99']:.2f} ms",
        f"power: mean {stats['power_mean_w']:.3f} W, peak {stats['power_peak_w']:.3f} W (cap "
        f"{stats['power_budget_w']:g} W); saturated blocks: {stats['voltage_saturated']} voltage, "
        f"{stats['power_saturated']} power",
    ]
    if stats["faults"]:
        lines.append(f"faults: {stats['faults']} ({', '.join(stats['fault_causes'])}): the drive ramped to 0 each time "
                     "and came back with the next valid data")
    return [line.replace("nan", "n/a") for line in lines]
