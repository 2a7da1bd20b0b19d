"""``tpad-rt serve``'s network side: the WebSocket API, the page's static files, and OSC over UDP, on one
asyncio loop in front of one :class:`~tpad_rt.engine.Renderer`.

API map
-------
Settings(host, port, osc_port, token, allowed_origins, texture_dirs)
    where to listen and who may connect
Server(renderer, settings, texture_label, clock=None)
    ``await run(stop)``: serve until ``stop`` is set or the renderer fails (re-raised);
    ``port``, ``osc_port`` (bound, also when 0 was asked), ``counters``

docs/serve.md is the contract. One loop thread runs everything: a message is read,
checked (:mod:`tpad_rt.serve.protocol`), limited (:class:`~tpad_rt.serve.core.TokenBucket`)
and acted on before the next; the renderer's own threads render. Loading a texture
(compiling it, drawing its map) runs in a worker thread, up to MAX_TEXTURE_LOADS at once,
an inline texture's text read in a parser process (1 MiB of YAML takes seconds), and only
the swap into the renderer holds the texture lock, so one client's texture holds up
nobody else's messages; the one requested last wins. The parser processes are started
with multiprocessing's ``spawn``, which imports the main script in each: a script that
runs a Server keeps its top level under ``if __name__ == "__main__":`` (``tpad-rt serve``
and ``python -m tpad_rt`` do). Errors go back as
``error`` messages and the connection stays open; only a message past MAX_FRAME_BYTES
(the WebSocket layer closes with 1009) or a failed handshake ends one.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import itertools
import logging
import math
import multiprocessing
import signal
import sys
import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from http import HTTPStatus
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs

from websockets.asyncio.server import ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request as HttpRequest
from websockets.http11 import Response

from tpad_rt.clock import Clock, MonotonicClock
from tpad_rt.version import __version__
from tpad_rt.errors import SampleError, printable
from tpad_rt.serve import protocol
from tpad_rt.json_text import json_safe, json_text
from tpad_rt.serve.core import (
    ClockMap, FingerOwner, TelemetryFeed, TextureLibrary, TokenBucket, colorbar_png, device_info, friction_map_png,
    parse_inline,
)
from tpad_rt.serve.osc import OscEndpoint
from tpad_rt.serve.protocol import ProtocolError, Request, Sample
from tpad_rt.shipped import texture_names

if TYPE_CHECKING:
    from tpad_rt.config import TextureFile
    from tpad_rt.engine import Renderer
    from tpad_rt.texture import CompiledTexture

#: A client's sustained and burst messages per second; finger samples per second; bytes per second.
MESSAGES_PER_S, MESSAGES_BURST = 1000.0, 200.0
SAMPLES_PER_S, SAMPLES_BURST = 4000.0, 2 * protocol.MAX_BATCH
BYTES_PER_S, BYTES_BURST = float(2 * protocol.MAX_MESSAGE_BYTES), float(2 * protocol.MAX_MESSAGE_BYTES)
#: Texture loads per second (each compiles; an image texture reads its file).
TEXTURES_PER_S, TEXTURES_BURST = 10.0, 10.0
#: ``device`` and ``stats`` requests per second (each computes the renderer's statistics).
HEAVY_PER_S = 20.0
#: Most WebSocket clients at once (more are refused with 503).
MAX_CLIENTS = 32
#: A client that leaves this many bytes of the server's messages unread is closed (1008).
MAX_UNREAD_BYTES = 1 << 20
#: Texture loads running or waiting at once, server-wide (more are refused as rate_limited).
MAX_TEXTURE_LOADS = 4
#: Processes reading inline textures' text (a 1 MiB text takes seconds of CPU: in a process of its own, it
#: shares no GIL with the loop that serves every client).
PARSER_PROCESSES = 2
#: At most one ``rate_limited`` error per this many seconds to a client (the count of dropped messages in it).
LIMIT_NOTICE_S = 0.25
#: Seconds a closing connection waits for the client's side of the close (Ctrl-C waits at most about this).
CLOSE_TIMEOUT_S = 1.0
#: The finger is freed when its holder sends nothing for this long (s); the kernel's watchdog ramped it already.
OWNER_IDLE_S = 1.0
#: The telemetry feed's pump period (s).
PUMP_S = 0.02
#: How often the renderer is checked for a failure (s).
CHECK_S = 0.1
#: Most OSC senders whose limits are kept (the oldest forgotten first).
MAX_OSC_SENDERS = 64
#: Headers a request may carry at most once (one Origin names one page; which of two Hosts or tokens counts
#: cannot be told).
SINGLE_HEADERS = ("Origin", "Host", "Authorization", "Sec-WebSocket-Key", "Sec-WebSocket-Version")
#: Most characters of a client's header value quoted back in a refusal.
MAX_SHOWN_CHARS = 100
#: The page's files (package data) and their content types.
STATIC_FILES = {"/": ("index.html", "text/html; charset=utf-8"),
                "/index.html": ("index.html", "text/html; charset=utf-8"),
                "/page.js": ("page.js", "text/javascript; charset=utf-8"),
                "/page.css": ("page.css", "text/css; charset=utf-8")}
_SECURITY_HEADERS = [("Cache-Control", "no-store"), ("X-Content-Type-Options", "nosniff"),
                     ("Content-Security-Policy", "default-src 'self'; connect-src 'self' ws: wss:; img-src 'self'; "
                      "script-src 'self'; style-src 'self'; frame-ancestors 'none'")]


@dataclass(frozen=True)
class Settings:
    """Where ``serve`` listens (``port`` 0: any free one; ``osc_port`` None: no OSC), the token clients must
    show (None: none), the page origins besides the server's own that may open the WebSocket, and the folders
    clients may name texture files in (the shipped textures' first)."""

    host: str = "127.0.0.1"
    port: int = 8765
    osc_port: int | None = 8766
    token: str | None = None
    allowed_origins: tuple[str, ...] = ()
    texture_dirs: tuple[Path, ...] = ()


@dataclass(eq=False)
class Client:
    """One WebSocket connection (or OSC sender): its limits, clock map and telemetry subscription."""

    name: str
    connection: ServerConnection | None = None
    clock: ClockMap = field(default_factory=ClockMap)
    messages: TokenBucket = field(default_factory=lambda: TokenBucket(MESSAGES_PER_S, MESSAGES_BURST))
    samples: TokenBucket = field(default_factory=lambda: TokenBucket(SAMPLES_PER_S, SAMPLES_BURST))
    bytes: TokenBucket = field(default_factory=lambda: TokenBucket(BYTES_PER_S, BYTES_BURST))
    textures: TokenBucket = field(default_factory=lambda: TokenBucket(TEXTURES_PER_S, TEXTURES_BURST))
    heavy: TokenBucket = field(default_factory=lambda: TokenBucket(HEAVY_PER_S, HEAVY_PER_S))
    dropped: int = 0
    noticed_s: float = -math.inf
    subscription: asyncio.Task[None] | None = None


class Server:
    """The API of ``tpad-rt serve`` in front of a started ``renderer`` (module docstring)."""

    def __init__(self, renderer: Renderer, settings: Settings, texture_label: str | None = None, *,
                 clock: Clock | None = None):
        self.renderer = renderer
        #: What the clients' budgets, the finger's idle time and OSC's budgets run on (default: the host's
        #: monotonic clock; tests give a VirtualClock to judge the budgets exactly).
        self.clock: Clock = MonotonicClock() if clock is None else clock
        self.settings = settings
        self.library = TextureLibrary(list(settings.texture_dirs), self._parse_inline)
        self._parsers: ProcessPoolExecutor | None = None
        self._parsers_lock = threading.Lock()
        self.owner = FingerOwner(OWNER_IDLE_S)
        self.feed = TelemetryFeed(renderer)
        self.counters: Counter[str] = Counter()
        self.port = settings.port
        self.osc_port = settings.osc_port
        self._clients: set[Client] = set()
        self._osc_senders: OrderedDict[tuple[str, int], Client] = OrderedDict()
        self._names = itertools.count(1)
        self._texture_lock = asyncio.Lock()
        self._texture_serial = 0
        self._texture_loads = 0
        self._texture_requests = self._texture_ticket = 0  # requests numbered in arrival order; the newest set
        self._texture_label = texture_label or ("none" if renderer.texture.kind == "none" else "the command line")
        self._map_png = friction_map_png(renderer.texture, renderer.device)
        self._colorbar_png = colorbar_png()
        self._static = {path: (resources.files("tpad_rt.serve").joinpath("static", name).read_bytes(), kind)
                        for path, (name, kind) in STATIC_FILES.items()}

    def now_s(self) -> float:
        """The server's :attr:`clock` (s)."""
        return self.clock.now_ns() * 1e-9

    # --- running ---------------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event, ready: asyncio.Event | None = None) -> None:
        """Serve until ``stop`` is set (connections closed with 1001, the finger lifted) or the renderer fails
        (its error re-raised); ``ready`` is set once listening (``port``/``osc_port`` then bound)."""
        with _one_line_logs(self.counters):
            await self._run(stop, ready)

    async def _run(self, stop: asyncio.Event, ready: asyncio.Event | None) -> None:
        loop = asyncio.get_running_loop()
        async with serve(self._connected, self.settings.host, self.settings.port, process_request=self._http,
                         process_response=self._handshake_done,
                         max_size=protocol.MAX_FRAME_BYTES, max_queue=16, compression=None,
                         close_timeout=CLOSE_TIMEOUT_S, server_header=f"tpad-rt/{__version__}") as server:
            self.port = next(iter(server.sockets)).getsockname()[1]
            osc = None
            if self.settings.osc_port is not None:
                osc = await OscEndpoint.open(loop, "127.0.0.1", self.settings.osc_port, self._osc_message,
                                           self.counters, self.clock)
                self.osc_port = osc.port
            tasks = [asyncio.create_task(self._pump()), asyncio.create_task(self._watch(stop))]
            if ready is not None:
                ready.set()
            try:
                await stop.wait()
            finally:
                for task in tasks:
                    task.cancel()
                if osc is not None:
                    osc.close()
                if self.owner.holder is not None:
                    self.renderer.lift()
                for client in self._clients:  # a telemetry send may wait on a client that does not read
                    if client.subscription is not None:
                        client.subscription.cancel()
                server.close(close_connections=True)
                with self._parsers_lock:
                    if self._parsers is not None:
                        self._parsers.shutdown(wait=False, cancel_futures=True)
        for task in tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]

    async def _pump(self) -> None:
        while True:
            self.feed.pump()
            await asyncio.sleep(PUMP_S)

    async def _watch(self, stop: asyncio.Event) -> None:
        """Set ``stop`` when the renderer fails, and raise its error."""
        try:
            while True:
                self.renderer.check()
                await asyncio.sleep(CHECK_S)
        finally:
            stop.set()

    # --- HTTP: the page, the map, the handshake's checks -----------------------------------------

    def _http(self, connection: ServerConnection, request: HttpRequest) -> Response | None:
        """The page's files, the friction map, or (for ``/ws``) None to go on with the handshake once the
        request is well-formed and the origin and the token pass; any other request gets its 4xx, counted."""
        self.counters["http_requests"] += 1
        try:
            return self._route(connection, request)
        except Exception as error:  # noqa: BLE001 - a bug: one counted line on stderr, a 500, keep serving
            self.counters["refused_internal"] += 1
            print(f"tpad-rt serve: internal error handling an HTTP request: {error!r} (please report it)",
                  file=sys.stderr, flush=True)
            return connection.respond(HTTPStatus.INTERNAL_SERVER_ERROR, "the server failed on this request; it "
                                      "keeps serving\n")

    def _route(self, connection: ServerConnection, request: HttpRequest) -> Response | None:
        path, _, query = request.path.partition("?")
        repeated = next((name for name in SINGLE_HEADERS if len(request.headers.get_all(name)) > 1), None)
        if repeated == "Origin":  # which page sent it cannot be told: not an allowed one
            self.counters["refused_origin"] += 1
            return connection.respond(HTTPStatus.FORBIDDEN, "a request with more than one Origin header comes from "
                                      "no page that may open this WebSocket\n")
        if repeated is not None:
            self.counters["refused_malformed"] += 1
            return connection.respond(HTTPStatus.BAD_REQUEST, f"a request has at most one {repeated} header\n")
        if path == "/ws":
            if len(self._clients) >= MAX_CLIENTS:
                self.counters["refused_full"] += 1
                return connection.respond(HTTPStatus.SERVICE_UNAVAILABLE, f"{MAX_CLIENTS} clients are connected "
                                          "already; try again when one has left\n")
            origin = request.headers.get("Origin")
            if origin is not None and origin not in self._origins(request):
                self.counters["refused_origin"] += 1
                return connection.respond(HTTPStatus.FORBIDDEN, f"origin {_shown(origin)} may not open this "
                                          "WebSocket (tpad-rt serve --allow-origin adds one)\n")
            if self.settings.token is not None:
                tokens = parse_qs(query).get("token", [])
                if len(tokens) > 1:
                    self.counters["refused_malformed"] += 1
                    return connection.respond(HTTPStatus.BAD_REQUEST, "a request shows at most one token\n")
                if not self._token_ok(tokens[0] if tokens else "", request.headers.get("Authorization", "")):
                    self.counters["refused_token"] += 1
                    return connection.respond(HTTPStatus.UNAUTHORIZED, "a token is needed: ws://HOST:PORT/ws?token="
                                              "... (the one tpad-rt serve printed)\n")
            return None
        if path == "/map.png":
            return self._response(self._map_png, "image/png")
        if path == "/colorbar.png":
            return self._response(self._colorbar_png, "image/png")
        if path in self._static:
            return self._response(*self._static[path])
        return connection.respond(HTTPStatus.NOT_FOUND, "not found: this server has /, /map.png, /colorbar.png and /ws\n")

    def _handshake_done(self, connection: ServerConnection, request: HttpRequest, response: Response) -> None:
        """Count a handshake the WebSocket layer itself refused (a bad or repeated Sec-WebSocket-Key, Upgrade,
        version): it answered 4xx, and says nothing on stderr."""
        if connection.protocol.handshake_exc is not None:
            self.counters["refused_malformed"] += 1

    def _response(self, body: bytes, kind: str) -> Response:
        headers = Headers([("Content-Type", kind), ("Content-Length", str(len(body))), *_SECURITY_HEADERS])
        return Response(200, "OK", headers, body)

    def _origins(self, request: HttpRequest) -> set[str]:
        """The origins whose pages may open the WebSocket: this server's own (as the browser reached it, and
        its loopback names), and ``allowed_origins``."""
        port = self.port
        own = {f"http://{name}:{port}" for name in ("127.0.0.1", "localhost", "[::1]", self.settings.host)}
        return own | set(self.settings.allowed_origins)

    def _token_ok(self, shown: str, authorization: str) -> bool:
        """Whether the URL's ``token`` or the ``Authorization`` header's bearer is this server's token (header
        bytes beyond ASCII are compared as they came)."""
        token = self.settings.token
        assert token is not None
        return hmac.compare_digest(shown.encode("utf-8", "surrogateescape"), token.encode()) or \
            hmac.compare_digest(authorization.encode("utf-8", "surrogateescape"), f"Bearer {token}".encode())

    # --- WebSocket -----------------------------------------------------------------------------

    async def _connected(self, connection: ServerConnection) -> None:
        client = Client(f"ws#{next(self._names)}", connection)
        self._clients.add(client)
        self.counters["connections"] += 1
        try:
            await connection.send(_wire(self._hello(client)))
            async for raw in connection:
                reply = await self._handle(client, raw)
                if reply is not None:
                    await connection.send(_wire(reply))
        except ConnectionClosed:
            pass
        finally:
            self._clients.discard(client)
            if client.subscription is not None:
                client.subscription.cancel()
            self._let_go(client)

    def _hello(self, client: Client) -> dict[str, Any]:
        return {
            "type": "hello", "protocol": protocol.PROTOCOL_VERSION, "server": f"tpad-rt {__version__}",
            "client": client.name, "device": device_info(self.renderer), "texture": self._texture_message(),
            "textures": texture_names(), "stream_t": self.renderer.now_s(),
            "limits": {"max_message_bytes": protocol.MAX_MESSAGE_BYTES, "max_batch": protocol.MAX_BATCH,
                       "messages_per_s": MESSAGES_PER_S, "samples_per_s": SAMPLES_PER_S,
                       "max_subscribe_hz": protocol.MAX_SUBSCRIBE_HZ, "finger_idle_s": OWNER_IDLE_S},
            "finger": self._finger_state(client),
        }

    async def _handle(self, client: Client, raw: str | bytes) -> dict[str, Any] | None:
        """Act on one message; the reply (an error included), or None."""
        now_s = self.now_s()
        self.counters["messages"] += 1
        size = len(raw) if isinstance(raw, bytes) or raw.isascii() else len(raw.encode("utf-8", "surrogatepass"))
        try:
            if size > protocol.MAX_MESSAGE_BYTES:  # refused unread
                raise ProtocolError("too_large", f"a message of {size:,} bytes; at most {protocol.MAX_MESSAGE_BYTES:,}")
            if not client.bytes.take(size, now_s):  # what parsing costs
                return self._limited(client, now_s, f"bytes (at most {BYTES_PER_S:,.0f} a second)")
            request = protocol.parse(raw)
        except ProtocolError as problem:
            if not client.messages.take(1, now_s):
                return self._limited(client, now_s, self._message_limit, problem.request_id)
            return self._refused(problem)
        if not client.messages.take(1, now_s):
            return self._limited(client, now_s, self._message_limit, request.id)
        try:
            return await self._act(client, request, now_s)
        except ProtocolError as problem:
            return self._refused(problem)
        except Exception as error:  # noqa: BLE001 - a bug: say so to the client and on stderr, keep serving
            return self._refused(self.internal_error(error, request))

    def internal_error(self, error: Exception, request: Request) -> ProtocolError:
        """A bug met handling ``request``: one line on stderr, and the ``internal`` error for the client."""
        print(f"tpad-rt serve: internal error handling a {request.type} message: {error!r} (please report it)",
              file=sys.stderr, flush=True)
        return ProtocolError("internal", f"the server failed on this message ({type(error).__name__}); it keeps "
                             "serving", request.id, request.type)

    _message_limit = f"messages (at most {MESSAGES_PER_S:g} a second)"

    def _refused(self, problem: ProtocolError) -> dict[str, Any]:
        self.counters[f"error_{problem.code}"] += 1
        return problem.reply()

    def _limited(self, client: Client, now_s: float, what: str, request_id: Any = None) -> dict[str, Any] | None:
        """Drop the message (too many ``what``): a ``rate_limited`` error carrying ``request_id`` when the message
        had one (a client waiting for a reply gets one), else at most one every LIMIT_NOTICE_S, saying how many
        were dropped since the last."""
        client.dropped += 1
        self.counters["rate_limited"] += 1
        if request_id is None and now_s - client.noticed_s < LIMIT_NOTICE_S:
            return None
        client.noticed_s, dropped, client.dropped = now_s, client.dropped, 0
        return protocol.error("rate_limited", f"too many {what}: {dropped} message{'s' * (dropped != 1)} dropped",
                              request_id)

    async def _act(self, client: Client, request: Request, now_s: float) -> dict[str, Any] | None:
        kind = request.type
        if kind == "finger" or kind == "fingers":
            samples = [request] if isinstance(request, protocol.Finger) else request.samples  # type: ignore[union-attr]
            if not client.samples.take(len(samples), now_s):
                return self._limited(client, now_s, f"finger samples (at most {SAMPLES_PER_S:g} a second)", request.id)
            self.push(client, samples, request.id)  # type: ignore[arg-type]
            return None
        if isinstance(request, protocol.Lift):
            self.lift(client, request.t, request.id)
            return None
        if isinstance(request, protocol.SetTexture):
            if not client.textures.take(1, now_s):
                return self._limited(client, now_s, f"textures (at most {TEXTURES_PER_S:g} a second)", request.id)
            await self.set_texture(request, client)
            return None
        if isinstance(request, (protocol.DeviceInfo, protocol.Stats)) and not client.heavy.take(1, now_s):
            return self._limited(client, now_s, f"device and stats requests (at most {HEAVY_PER_S:g} a second)",
                                 request.id)
        if isinstance(request, protocol.DeviceInfo):
            return {**device_info(self.renderer), **_echo(request)}
        if isinstance(request, protocol.Subscribe):
            self._subscribe(client, request.rate_hz)
            return {"type": "subscribed", "rate_hz": request.rate_hz, **_echo(request)}
        if isinstance(request, protocol.Stats):
            return {"type": "stats", "renderer": json_safe(self.renderer.stats()),
                    "server": {"clients": len(self._clients), "finger": self._finger_state(client),
                               **dict(self.counters)}, **_echo(request)}
        assert isinstance(request, protocol.Ping)
        return {"type": "pong", "t": request.t, "stream_t": self.renderer.now_s(), **_echo(request)}

    # --- the finger ------------------------------------------------------------------------------

    def push(self, client: Client, samples: list[Sample], request_id: Any = None) -> None:
        """Push ``samples`` for ``client`` (it takes the finger if free), their times mapped onto the stream
        clock; ProtocolError ``finger_busy`` or ``bad_sample`` (the renderer's SampleError: nothing of the
        message after the bad sample is pushed)."""
        now_s = self.now_s()
        if not self.owner.free_for(client, now_s):
            raise ProtocolError("finger_busy", f"another client ({getattr(self.owner.holder, 'name', '?')}) has the "
                                f"finger until it lifts, disconnects or sends nothing for {OWNER_IDLE_S:g} s",
                                request_id, "finger")
        stamped = [sample.t for sample in samples if sample.t is not None]
        offset_s = client.clock.update(max(stamped), self.renderer.now_s()) if stamped else 0.0
        pushed = 0
        try:
            for sample in samples:
                t = None if sample.t is None else sample.t + offset_s
                self.renderer.push_finger(sample.x_mm, sample.y_mm, sample.force_n, t)
                pushed += 1
        except SampleError as problem:
            raise ProtocolError("bad_sample", str(problem), request_id, "finger") from None
        finally:
            if pushed:
                self.counters["samples"] += pushed
                previous = self.owner.holder
                self.owner.claim(client, now_s)
                if previous is not client:
                    self._announce_owner()

    def lift(self, client: Client, t: float | None, request_id: Any = None) -> None:
        """The holder's finger leaves the plate (at client time ``t``); from another client ignored when nobody
        holds it (or its holder is idle), ``finger_busy`` when another does."""
        if self.owner.holder is not client:
            if self.owner.holder_at(self.now_s()) is not None:
                raise ProtocolError("finger_busy", "another client has the finger: only it can lift it",
                                    request_id, "lift")
            return
        mapped = None
        if t is not None and client.clock.offset_s is not None:
            mapped = t + client.clock.offset_s
        try:
            self.renderer.lift(mapped)
        except SampleError as problem:
            self.renderer.lift()
            raise ProtocolError("bad_sample", str(problem), request_id, "lift") from None
        finally:
            self.owner.release(client)
            self._announce_owner()

    def _let_go(self, client: Client) -> None:
        """A client left: lift its finger if it held it."""
        if self.owner.holder is client:
            self.renderer.lift()
            self.owner.release(client)
            self._announce_owner()

    def _finger_state(self, client: Client) -> dict[str, Any]:
        holder = self.owner.holder_at(self.now_s())
        return {"held": holder is not None, "yours": holder is client,
                "holder": getattr(holder, "name", None), "policy": "first-come, until lift, disconnect or "
                f"{OWNER_IDLE_S:g} s idle"}

    def _announce_owner(self) -> None:
        for client in list(self._clients):
            self._push(client, {"type": "finger", **self._finger_state(client)})

    def _push(self, client: Client, message: dict[str, Any]) -> None:
        """Queue ``message`` for ``client`` without waiting (a broadcast); a client that has left more than
        MAX_UNREAD_BYTES unread is closed (1008) instead: it does not read, and would grow without bound."""
        connection = client.connection
        if connection is None:
            return
        unread = connection.transport.get_write_buffer_size() if connection.transport is not None else 0
        if unread > MAX_UNREAD_BYTES:
            self.counters["closed_slow"] += 1
            asyncio.ensure_future(connection.close(1008, f"too slow: {unread} bytes unread"))
            return
        broadcast([connection], _wire(message))

    # --- textures --------------------------------------------------------------------------------

    async def set_texture(self, request: protocol.SetTexture, client: Client | None = None) -> None:
        """Load, compile and render ``request``'s texture, then tell every client (the requester's copy
        carries its ``id``); ProtocolError ``texture``/``forbidden_path``, or ``texture`` when a texture
        requested after it was set first (the later request wins)."""
        if self._texture_loads >= MAX_TEXTURE_LOADS:
            raise ProtocolError("rate_limited", f"{self._texture_loads} textures are loading already; send this one "
                                "once one is set", request.id, "texture")
        self._texture_loads += 1
        self._texture_requests += 1
        ticket = self._texture_requests
        try:
            compiled, label, png = await asyncio.to_thread(self._prepare_texture, request)
        finally:
            self._texture_loads -= 1
        async with self._texture_lock:  # held only to swap: the work above runs in parallel, off the loop
            if ticket < self._texture_ticket:
                raise ProtocolError("texture", "a texture requested after this one was set first; this one is not",
                                    request.id, "texture")
            self._texture_ticket = ticket
            self.renderer.set_texture(compiled)
            self._texture_serial += 1
            self._texture_label, self._map_png = label, png
        message = self._texture_message()
        self.counters["textures_set"] += 1
        for other in list(self._clients):
            self._push(other, {**message, **_echo(request)} if other is client else message)

    def _prepare_texture(self, request: protocol.SetTexture) -> tuple[CompiledTexture, str, bytes]:
        """``(compiled texture, its label, its friction map as PNG)`` of ``request`` (run in a worker thread:
        parsing 1 MiB of YAML takes seconds)."""
        compiled, label = self.library.load(request)
        return compiled, label, friction_map_png(compiled, self.renderer.device)

    def _parse_inline(self, text: str, base_dir: Path, folders: list[Path]) -> tuple[TextureFile | None, list[str]]:
        """:func:`~tpad_rt.serve.core.parse_inline` in a parser process (started on first use): called from a
        worker thread, which it blocks, while the process's CPU time shares no GIL with the loop."""
        with self._parsers_lock:
            if self._parsers is None:
                self._parsers = ProcessPoolExecutor(PARSER_PROCESSES, mp_context=multiprocessing.get_context("spawn"),
                                                    initializer=_parser_started)
            parsers = self._parsers
        try:
            return parsers.submit(parse_inline, text, base_dir, folders).result()
        except BrokenProcessPool:  # a parser process died (killed, out of memory): new ones for the next text
            with self._parsers_lock:
                if self._parsers is parsers:
                    self._parsers = None
            return None, ["yaml: not read: the process reading it ended (out of memory?)"]
        except RuntimeError:  # shut down: the server is stopping
            return None, ["yaml: not read: the server is stopping"]

    def _texture_message(self) -> dict[str, Any]:
        texture = self.renderer.texture
        return {"type": "texture", "source": self._texture_label, "kind": texture.kind,
                "description": texture.description, "map": f"/map.png?v={self._texture_serial}"}

    # --- telemetry -------------------------------------------------------------------------------

    def _subscribe(self, client: Client, rate_hz: float) -> None:
        if client.subscription is not None:
            client.subscription.cancel()
            client.subscription = None
        if rate_hz > 0:
            client.subscription = asyncio.create_task(self._send_telemetry(client, max(rate_hz,
                                                                                   protocol.MIN_SUBSCRIBE_HZ)))

    async def _send_telemetry(self, client: Client, rate_hz: float) -> None:
        assert client.connection is not None
        since_t = self.renderer.now_s()
        period_s = 1.0 / rate_hz
        next_s = time.monotonic()
        try:
            while True:
                next_s = max(next_s + period_s, time.monotonic())
                await asyncio.sleep(next_s - time.monotonic())
                summary = self.feed.summary(since_t)
                if summary is not None:
                    since_t = summary["t"]
                    await client.connection.send(_wire(summary))
        except ConnectionClosed:
            pass

    # --- OSC -------------------------------------------------------------------------------------

    async def _osc_message(self, sender: tuple[str, int], data: dict[str, Any]) -> dict[str, Any] | None:
        """One OSC message as a request dict (:mod:`tpad_rt.serve.osc`): its reply; ProtocolError as for
        WebSocket."""
        client = self._osc_senders.get(sender)
        if client is None:
            client = Client(f"osc {sender[0]}:{sender[1]}")
            self._osc_senders[sender] = client
            while len(self._osc_senders) > MAX_OSC_SENDERS:
                _, forgotten = self._osc_senders.popitem(last=False)
                self._let_go(forgotten)
        self._osc_senders.move_to_end(sender)
        now_s = self.now_s()
        self.counters["osc_messages"] += 1
        if not client.messages.take(1, now_s):
            client.dropped += 1
            self.counters["rate_limited"] += 1
            raise ProtocolError("rate_limited", "too many OSC messages")
        request = protocol.validate(data)
        try:
            return await self._act(client, request, now_s)
        except ProtocolError:
            raise
        except Exception as error:  # noqa: BLE001 - as for a WebSocket message
            raise self.internal_error(error, request) from None


class _OneLine(logging.Handler):
    """A library's log record (websockets, asyncio, python-osc) as one counted line on stderr, its traceback
    left out: what a client sends never prints a traceback."""

    def __init__(self, counters: Counter[str]):
        super().__init__(logging.WARNING)
        self.counters = counters

    def emit(self, record: logging.LogRecord) -> None:
        self.counters["internal_logged"] += 1
        why = f": {record.exc_info[1]!r}" if record.exc_info and record.exc_info[1] is not None else ""
        text = printable(f"{record.getMessage()}{why}")
        print(f"tpad-rt serve: {record.name}: {text[:300]} (please report it)", file=sys.stderr, flush=True)


def _parser_started() -> None:
    """In a parser process: Ctrl-C (SIGINT to the terminal's process group) is the server's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _one_line_logs(counters: Counter[str]) -> Iterator[None]:
    """While open, every log record of WARNING and above (any library's) is one counted line (_OneLine)."""
    handler = _OneLine(counters)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)


def _wire(message: dict[str, Any]) -> str:
    """``message`` as the JSON text sent: NaN and infinities as null (JSON has neither; browsers refuse them)."""
    return json_text(message)


def _shown(value: str) -> str:
    """A header value as quoted back: printable ASCII (other bytes escaped), at most MAX_SHOWN_CHARS."""
    text = printable(value.encode("utf-8", "surrogateescape").decode("ascii", "backslashreplace"))
    return text if len(text) <= MAX_SHOWN_CHARS else text[:MAX_SHOWN_CHARS - 3] + "..."


def _echo(request: Request) -> dict[str, Any]:
    """``{"id": ...}`` when the request had one."""
    return {"id": request.id} if request.id is not None else {}
