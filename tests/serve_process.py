"""``tpad-rt serve`` in its own process for the tests: started on free ports, stopped by PID with a signal.

Helpers to talk to it: a WebSocket client that waits for a given message type (no sleeps:
every wait is for a message, bounded by REPLY_TIMEOUT_S), and an OSC socket.
"""

from __future__ import annotations

import json
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from websockets.sync.client import ClientConnection, connect

from cli_run import REPO
from tpad_rt.clock import Clock

#: Longest wait for the server's first line (a first run in a fresh numba cache compiles the kernels).
START_TIMEOUT_S = 120.0
#: Longest wait for one expected message: a failure bound, never a timing assertion (a test that waits this
#: long has failed; a loaded machine takes seconds for the slowest reply, a 900 KiB texture's refusal).
REPLY_TIMEOUT_S = 60.0
_SERVING = re.compile(r"serving http://(\S+?):(\d+)/ \(WebSocket \S+(?:, OSC udp://127\.0\.0\.1:(\d+))?\)")


class Serve:
    """``python -m tpad_rt serve ARGS --port 0 --osc-port 0`` until :meth:`stop`."""

    def __init__(self, *args: str, port_args: tuple[str, ...] = ("--port", "0", "--osc-port", "0")):
        self.process = subprocess.Popen([sys.executable, "-m", "tpad_rt", "serve", *args, *port_args], cwd=REPO,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._lines: queue.Queue[str | None] = queue.Queue()
        self.stdout: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        self.host, self.port, self.osc_port = self._wait_serving()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._lines.put(line)
        self._lines.put(None)

    def _wait_serving(self) -> tuple[str, int, int | None]:
        while True:
            try:
                line = self._lines.get(timeout=START_TIMEOUT_S)
            except queue.Empty:
                self.process.kill()
                raise AssertionError("tpad-rt serve printed no 'serving' line") from None
            if line is None:
                status = self.process.wait()
                raise AssertionError(f"tpad-rt serve ended ({status}) before serving: {self.stderr_text()}")
            self.stdout.append(line)
            found = _SERVING.search(line)
            if found:
                osc = found.group(3)
                return found.group(1), int(found.group(2)), int(osc) if osc else None

    def stderr_text(self) -> str:
        return self.process.stderr.read() if self.process.stderr else ""

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/ws"

    @property
    def http_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def stop(self, sig: int = signal.SIGINT) -> tuple[int, str, str]:
        """Send ``sig`` and wait: (exit status, all of stdout, stderr)."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        status = self.process.wait(timeout=START_TIMEOUT_S)
        while (line := self._lines.get(timeout=REPLY_TIMEOUT_S)) is not None:
            self.stdout.append(line)
        return status, "".join(self.stdout), self.stderr_text()

    def __enter__(self) -> Serve:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


class Client:
    """A WebSocket client of the server: JSON in and out, messages kept until asked for."""

    def __init__(self, url: str, **options: Any):
        # __enter__ connects on every websockets version (17.1 made connect() a context manager to be entered).
        # max_queue=None: the client's thread keeps reading whatever the test has not asked for yet (telemetry),
        # so that a close from the server is seen at once, not after the client's close_timeout.
        self.connection: ClientConnection = connect(url, open_timeout=REPLY_TIMEOUT_S, max_size=None, max_queue=None,
                                                    **options).__enter__()
        self.hello = self.expect("hello")

    def send(self, message: dict[str, Any] | str | bytes) -> None:
        self.connection.send(message if isinstance(message, (str, bytes)) else json.dumps(message))

    def receive(self, deadline: float | None = None) -> dict[str, Any]:
        """The next message; TimeoutError when none comes by ``deadline`` (time.monotonic; default
        REPLY_TIMEOUT_S from now)."""
        left = REPLY_TIMEOUT_S if deadline is None else deadline - time.monotonic()
        return json.loads(self.connection.recv(timeout=max(left, 0.0)))

    def expect(self, kind: str, where: Callable[[dict[str, Any]], bool] = lambda message: True) -> dict[str, Any]:
        """The next message of type ``kind`` that satisfies ``where`` (others read past)."""
        return self.first(lambda message: message["type"] == kind and where(message), f"'{kind}' message")

    def first(self, where: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        """The next message that satisfies ``where`` (others read past); AssertionError naming ``what`` and the
        last message read when none has within REPLY_TIMEOUT_S."""
        deadline = time.monotonic() + REPLY_TIMEOUT_S
        last: dict[str, Any] | None = None
        while True:
            try:
                message = self.receive(deadline)
            except TimeoutError:
                raise AssertionError(f"no {what} as expected within {REPLY_TIMEOUT_S:g} s; the last read: "
                                     f"{last}") from None
            if where(message):
                return message
            last = message

    def request(self, message: dict[str, Any], kind: str) -> dict[str, Any]:
        """Send ``message`` with a fresh id; the reply of type ``kind``, or the ``error``, that carries it."""
        self._ids = getattr(self, "_ids", 0) + 1
        request_id = self._ids
        self.send({**message, "id": request_id})
        return self.first(lambda m: m.get("id") == request_id and m["type"] in (kind, "error"),
                          f"'{kind}' or error reply to #{request_id}")

    def close(self) -> None:
        self.connection.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def osc_socket() -> socket.socket:
    """A UDP socket on loopback for sending OSC and reading the replies."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(REPLY_TIMEOUT_S)
    return sock


def stopped_by_signal_cleanly(serve: Serve, sig: int = signal.SIGINT) -> str:
    """Stop ``serve`` with ``sig``; assert exit 0, no traceback; its stdout."""
    status, out, err = serve.stop(sig)
    assert status == 0, (status, err)
    assert "Traceback" not in err, err
    return out


class ServeThread:
    """``tpad-rt serve``'s Server in this process, on an asyncio loop in a thread, in front of a started
    Renderer on ``null://`` (loopback, free ports): for tests that reach into the server (a gate in its texture
    loading, its counters) while its clients are real sockets. ``clock``: the server's (its budgets'; a
    VirtualClock stands still until the test advances it). ``server``, ``port``, ``osc_port``; a context
    manager."""

    def __init__(self, clock: Clock | None = None) -> None:
        import asyncio

        from tpad_rt.engine import Renderer
        from tpad_rt.serve.server import Server, Settings
        from tpad_rt.shipped import TEXTURES_DIR

        self.renderer = Renderer(output="null://", texture=TEXTURES_DIR / "grating.yaml")
        self.renderer.start()
        self.server = Server(self.renderer, Settings(port=0, osc_port=0, texture_dirs=(TEXTURES_DIR,)), clock=clock)
        self.loop = asyncio.new_event_loop()
        self._stop = asyncio.Event()
        self._ready = threading.Event()
        self.failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="serve", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S) or self.failure is not None:
            raise AssertionError(f"the server did not start: {self.failure!r}")

    def _run(self) -> None:
        import asyncio

        async def serve() -> None:
            ready = asyncio.Event()
            task = asyncio.create_task(self.server.run(self._stop, ready))
            await asyncio.wait([task, asyncio.create_task(ready.wait())], return_when=asyncio.FIRST_COMPLETED)
            self._ready.set()
            await task

        try:
            self.loop.run_until_complete(serve())
        except BaseException as error:  # noqa: BLE001 - reported by the constructor or close()
            self.failure = error
            self._ready.set()

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def osc_port(self) -> int | None:
        return self.server.osc_port

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/ws"

    def close(self) -> None:
        """Stop the server (its loop) and the renderer; AssertionError if the server failed."""
        self.loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(START_TIMEOUT_S)
        self.renderer.stop()
        assert self.failure is None and not self._thread.is_alive(), self.failure

    def __enter__(self) -> ServeThread:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
