"""tpad-rt serve against a hostile client, on real sockets: raw handshakes (repeated, case-varied, empty, huge
and non-ASCII headers), malformed OSC datagrams and floods of them, extreme numbers, and a large texture
being parsed. Each gets a clean refusal, counted; other clients' pings are answered meanwhile (shown by
order, never by time: a gate holds the parse, counters show the flood arriving; the flood's budget on a
VirtualClock); and the server's stderr stays free of tracebacks and library warnings."""

from __future__ import annotations

import base64
import json
import os
import re
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from serve_process import REPLY_TIMEOUT_S, Client, Serve, ServeThread, osc_socket
from test_config_parse_cost import unknown_keys_text
from tpad_rt.clock import VirtualClock
from tpad_rt.config.messages import MAX_LISTED_ERRORS
from tpad_rt.serve import osc as osc_limits

TOKEN = "s3cret-token"
KEY = base64.b64encode(b"0123456789abcdef").decode()


def stray_stderr(err: str) -> list[str]:
    """Lines on a server's stderr other than the kernels' compile notice (a first run in a fresh cache)."""
    return [line for line in err.splitlines() if not line.startswith("tpad-rt: compil")]


def stopped_clean(serve: Serve) -> str:
    """Stop ``serve``; assert exit 0 and nothing on stderr but the compile notice; its stdout."""
    status, out, err = serve.stop()
    assert status == 0 and stray_stderr(err) == [], err
    return out


@pytest.fixture(scope="module")
def server() -> Iterator[Serve]:
    serve = Serve("--output", "null://", "--token", TOKEN)
    with serve:
        yield serve
        stopped_clean(serve)


# --- handshakes -----------------------------------------------------------------------------------------------

def handshake(port: int, head: bytes) -> bytes:
    """Send ``head`` (a request's line and headers, without the blank line) on a new TCP connection; the
    response's status line (empty when the server closed without one)."""
    with socket.create_connection(("127.0.0.1", port), timeout=REPLY_TIMEOUT_S) as sock:
        sock.sendall(head + b"\r\n\r\n")
        data = b""
        while b"\r\n" not in data:
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
    return data.split(b"\r\n")[0]


def upgrade(port: int, *extra: str, path: str = f"/ws?token={TOKEN}", key: bool = True) -> bytes:
    lines = [f"GET {path} HTTP/1.1", f"Host: 127.0.0.1:{port}", "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Version: 13", *([f"Sec-WebSocket-Key: {KEY}"] if key else []), *extra]
    return "\r\n".join(lines).encode("latin-1")


#: (what, extra header lines or a whole request, the status it must get). PORT is the server's.
HANDSHAKES: list[tuple[str, dict[str, object], int]] = [
    ("well-formed", {}, 101),
    ("two Origins, both allowed", {"extra": ("Origin: http://127.0.0.1:PORT", "Origin: http://127.0.0.1:PORT")}, 403),
    ("two Origins, one allowed", {"extra": ("Origin: http://127.0.0.1:PORT", "Origin: http://evil.example")}, 403),
    ("two Origins in other cases", {"extra": ("origin: http://evil.example", "ORIGIN: http://127.0.0.1:PORT")}, 403),
    ("an empty Origin", {"extra": ("Origin: ",)}, 403),
    ("Origin null", {"extra": ("Origin: null",)}, 403),
    ("an Origin of 8,000 characters", {"extra": ("Origin: http://" + "a" * 8000,)}, 403),
    ("an Origin beyond ASCII", {"extra": ("Origin: http://\xff\xfe.example",)}, 403),
    ("two Authorization headers", {"path": "/ws", "extra": (f"Authorization: Bearer {TOKEN}",
                                                            "authorization: Bearer wrong-token")}, 400),
    ("two Authorization headers, both right", {"path": "/ws", "extra": (f"Authorization: Bearer {TOKEN}",) * 2}, 400),
    ("the token as a header", {"path": "/ws", "extra": (f"Authorization: Bearer {TOKEN}",)}, 101),
    ("an empty Authorization", {"path": "/ws", "extra": ("Authorization: ",)}, 401),
    ("an Authorization beyond ASCII", {"path": "/ws", "extra": ("Authorization: Bearer \xff\xfe",)}, 401),
    ("two tokens in the URL", {"path": f"/ws?token={TOKEN}&token=wrong-token"}, 400),
    ("a token beyond ASCII", {"path": "/ws?token=%ff%fe"}, 401),
    ("no token", {"path": "/ws"}, 401),
    ("two Hosts", {"extra": ("Host: evil.example",)}, 400),
    ("two Hosts for the page", {"path": "/", "extra": ("Host: evil.example",)}, 400),
    ("two Sec-WebSocket-Keys", {"extra": (f"Sec-WebSocket-Key: {KEY}",)}, 400),
    ("no Sec-WebSocket-Key", {"key": False}, 400),
    ("two Sec-WebSocket-Versions", {"extra": ("Sec-WebSocket-Version: 8",)}, 400),
    ("a header of 100 KB", {"extra": ("X-Big: " + "a" * 100_000,)}, 431),
    ("300 headers", {"extra": tuple(f"X-{index}: a" for index in range(300))}, 431),
    ("not HTTP", {"raw": b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03"}, 0),
]


def test_hostile_handshakes_get_a_clean_refusal_each_counted() -> None:
    with Serve("--output", "null://", "--token", TOKEN, "--no-osc", port_args=("--port", "0")) as server:
        counters = refusals(server)
        out = stopped_clean(server)
    assert counters["refused_origin"] >= 7 and counters["refused_malformed"] >= 6, counters
    summary = re.search(r"^HTTP: (\d+) requests?, (\d+) refused \((\d+) malformed, (\d+) origin, (\d+) token\)$", out,
                        re.M)
    assert summary is not None, out
    assert [int(count) for count in summary.groups()[1:]] == [
        sum(counters[f"refused_{why}"] for why in ("malformed", "origin", "token")), counters["refused_malformed"],
        counters["refused_origin"], counters["refused_token"]]


def refusals(server: Serve) -> dict[str, int]:
    """Send every hostile handshake to ``server``, asserting the status each gets; its counters then."""
    refused = 0
    for what, case, status in HANDSHAKES:
        extra = [line.replace("PORT", str(server.port)) for line in case.get("extra", ())]  # type: ignore[attr-defined]
        head = case["raw"] if "raw" in case else upgrade(server.port, *extra, **{  # type: ignore[arg-type]
            key: case[key] for key in ("path", "key") if key in case})
        line = handshake(server.port, head)  # type: ignore[arg-type]
        got = int(line.split()[1]) if line else 0
        assert got == status, (what, line)
        refused += 400 <= got < 500 and case.get("path") != "/"
    with Client(f"{server.ws_url}?token={TOKEN}") as client:
        counters = client.request({"type": "stats"}, "stats")["server"]
    counted = sum(value for key, value in counters.items() if key.startswith("refused_"))
    assert counted >= refused - 2, counters  # less the two 431s, which the WebSocket layer answers unparsed
    return counters


def test_a_browser_client_with_two_origins_is_refused_like_any_foreign_page(server: Serve) -> None:
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus) as refused:
        Client(f"{server.ws_url}?token={TOKEN}", origin=f"http://127.0.0.1:{server.port}",
               additional_headers=[("Origin", "http://evil.example")])
    assert refused.value.response.status_code == 403
    assert b"more than one Origin" in refused.value.response.body


# --- OSC ------------------------------------------------------------------------------------------------------

def osc_message(address: str, *arguments: tuple[Any, str]) -> bytes:
    builder = OscMessageBuilder(address)
    for value, tag in arguments:
        builder.add_arg(value, tag)
    return builder.build().dgram


def bundle(*elements: bytes) -> bytes:
    """A bundle (time tag: immediately) of already-built elements."""
    return b"#bundle\0" + struct.pack(">Q", IMMEDIATELY) + b"".join(struct.pack(">i", len(e)) + e for e in elements)


PING = osc_message("/tpad/ping", (7.0, "d"))
#: (what, datagram, a fragment of the error reply).
BAD_DATAGRAMS: list[tuple[str, bytes, str]] = [
    ("empty", b"", "element of 0 bytes"),
    ("unaligned", b"\xff garbage", "multiple of 4"),
    ("a bundle element of negative size", bundle(PING)[:16] + struct.pack(">i", -4) + PING, "size -4"),
    ("a bundle element of size 0", bundle(PING)[:16] + struct.pack(">i", 0) + PING, "size 0"),
    ("a bundle element past its end", bundle(PING)[:16] + struct.pack(">i", 4096) + PING, "size 4096"),
    ("a bundle cut in its time tag", b"#bundle\0\0\0\0\0", "time tag"),
    ("bundles nested 5 deep", bundle(bundle(bundle(bundle(bundle(PING))))), "nested deeper"),
    ("an element neither bundle nor message", bundle(b"xyz\0"), "starts with '/'"),
    ("33 messages", bundle(*[PING] * 33), "more than 32 messages"),
    ("a datagram over 8 KiB", bundle(*[osc_message("/tpad/texture", ("x" * 4000, "s"))] * 3), "at most 8,192"),
    ("a blob", osc_message("/tpad/finger", (b"blob", "b")), "type tag 'b'"),
    ("a MIDI argument", osc_message("/tpad/finger", ((1, 2, 3, 4), "m")), "type tag 'm'"),
    ("an array", b"/tpad/finger\0\0\0\0,[f]\0\0\0\0" + struct.pack(">f", 1.0), "type tag '['"),
    ("tags longer than the arguments", b"/tpad/finger\0\0\0\0,ffd\0\0\0\0" + struct.pack(">ff", 1, 2), "shorter"),
    ("an address not UTF-8", b"/\x80pad/ping\0\0,\0\0\0", "address is not UTF-8"),
    ("an address without NUL", b"/tpad/finger", "address without its terminating NUL"),
    ("a type tag string without NUL", b"/a\0\0,fff", "type tag string without"),
    ("a string argument without NUL", b"/tpad/texture\0\0\0,s\0\0abcd", "string argument without"),
    ("type tags not starting with a comma", b"/a\0\0ff\0\0", "start with ','"),
]


def osc_reply(sock: socket.socket) -> OscMessage:
    return OscMessage(sock.recv(65536))


def test_each_malformed_datagram_gets_one_error_and_python_osc_never_sees_it(server: Serve) -> None:
    assert server.osc_port is not None
    with osc_socket() as sock:
        for what, datagram, fragment in BAD_DATAGRAMS:
            sock.sendto(datagram, ("127.0.0.1", server.osc_port))
            reply = osc_reply(sock)
            assert reply.address == "/tpad/error" and reply.params[0] == "bad_message", (what, reply.params)
            assert fragment in reply.params[1], (what, reply.params[1])
            sock.sendto(PING, ("127.0.0.1", server.osc_port))  # and the server still answers
            assert osc_reply(sock).address == "/tpad/pong", what
        sock.sendto(bundle(PING, bundle(PING, osc_message("/tpad/warp"))), ("127.0.0.1", server.osc_port))
        replies = sorted(osc_reply(sock).address for _ in range(3))
        assert replies == ["/tpad/error", "/tpad/pong", "/tpad/pong"]  # nested, well formed: each message handled


#: Bad datagrams the server must have received while one client's pings were answered, and the pings.
FLOOD_SEEN = 2000
PINGS = 12


def _wait_for(condition: Callable[[], bool]) -> None:
    """Until ``condition()`` holds; AssertionError after REPLY_TIMEOUT_S (a failure bound, never what is judged)."""
    deadline = time.monotonic() + REPLY_TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "the condition never held"
        threading.Event().wait(0.001)


def test_pings_are_answered_while_bad_bundles_stream_in() -> None:
    """A sender floods the OSC port with bad bundles (of the kinds that hung or slowed the loop) as fast as it
    can; meanwhile a WebSocket client's pings are each answered, until the server's counters show FLOOD_SEEN
    datagrams arrived between the first and the last. The server's clock (a VirtualClock) stands still: past
    its burst, every datagram is over the server-wide budget, dropped unread and counted, however fast the
    host sends them."""
    flood = [datagram for _, datagram, _ in BAD_DATAGRAMS] + \
        [bundle(*[osc_message("/tpad/warp", (1.0, "f"))] * osc_limits.MAX_DATAGRAM_MESSAGES)]
    with ServeThread(VirtualClock()) as serve, osc_socket() as sock, Client(serve.ws_url) as client:
        assert serve.osc_port is not None
        counters = serve.server.counters
        stop = threading.Event()

        def send() -> None:
            sent = 0
            while not stop.is_set():
                try:
                    sock.sendto(flood[sent % len(flood)], ("127.0.0.1", serve.osc_port))
                except OSError:  # ENOBUFS, or a refusal of the server's replies (ICMP): a flooder goes on
                    pass
                sent += 1

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        seen: list[int] = []  # osc_datagrams after each ping
        try:
            # PINGS pings, each once the flood has moved on by its share of FLOOD_SEEN: as many pings on a slow
            # host as on a fast one (the server's clock stands still, so the client's own message budget, burst
            # MESSAGES_BURST, never refills: a ping count that grew with the host's slowness would exhaust it).
            for k in range(PINGS):
                _wait_for(lambda: counters["osc_datagrams"] >= (seen[0] if seen else 0) + k * FLOOD_SEEN // (PINGS - 1))
                reply = client.request({"type": "ping", "t": 1.5}, "pong")
                assert reply["type"] == "pong" and reply["t"] == 1.5, reply
                seen.append(counters["osc_datagrams"])
        finally:
            stop.set()
            sender.join()
        assert seen[-1] - seen[0] >= FLOOD_SEEN
        burst = osc_limits.DATAGRAMS_PER_S / 10
        assert counters["osc_dropped"] >= counters["osc_datagrams"] - burst > 0, counters
        assert 0 < counters["error_bad_message"] <= burst, counters


# --- numbers --------------------------------------------------------------------------------------------------

EXTREMES = [1e308, -1e308, 1.7976931348623157e308, -1.7976931348623157e308, 5e-324, -5e-324, 2.2250738585072014e-308,
            1e-310, -0.0, 0.0, 2.0**53, -(2.0**63), 1e10, -1e10, 1.0000000001e10, 1e20]


def test_extreme_numbers_are_refused_or_taken_and_print_nothing() -> None:
    """Every extreme number in every numeric field of the WebSocket API and of OSC (doubles, floats, int64):
    taken, or refused with a counted error naming the field; never a warning on stderr."""
    serve = Serve("--output", "null://")
    with serve, osc_socket() as sock, Client(serve.ws_url) as client:
        assert serve.osc_port is not None
        errors = 0
        for value in EXTREMES:
            for message in ({"type": "finger", "x_mm": 10.0, "y_mm": 10.0, "t": value},
                            {"type": "fingers", "samples": [{"x_mm": 10.0, "y_mm": 10.0, "t": -value},
                                                            {"x_mm": 10.0, "y_mm": 10.0, "t": value}]},
                            {"type": "finger", "x_mm": value, "y_mm": 10.0}, {"type": "finger", "x_mm": 10.0,
                                                                               "y_mm": 10.0, "force_n": value},
                            {"type": "lift", "t": value}, {"type": "subscribe", "rate_hz": value}):
                client.send({**message, "id": "x"})
                reply = client.request({"type": "ping", "t": value}, "pong")  # after the message: its error came first
                assert reply["type"] == "pong" and json.dumps(reply["t"]) == json.dumps(value)
            for arguments in ([(10.0, "d"), (10.0, "d"), (0.5, "d"), (value, "d")], [(value, "d"), (10.0, "f")],
                              [(10, "i"), (10, "i"), (0.5, "f"), (int(max(min(value, 2**63 - 1), -2**63)), "h")],
                              [(10.0, "f"), (10.0, "f"), (float("nan"), "d")]):
                sock.sendto(osc_message("/tpad/finger", *arguments), ("127.0.0.1", serve.osc_port))
                sock.sendto(osc_message("/tpad/lift", (value, "d")), ("127.0.0.1", serve.osc_port))
                sock.sendto(PING, ("127.0.0.1", serve.osc_port))
                while (answer := osc_reply(sock)).address != "/tpad/pong":
                    assert answer.address == "/tpad/error" and answer.params[0] in ("bad_message", "bad_sample")
                    errors += 1
        counters = client.request({"type": "stats"}, "stats")["server"]
        client.close()
        stopped_clean(serve)
    assert errors > 0 and counters["error_bad_message"] > 0 and counters["samples"] > 0, counters


# --- a large texture ------------------------------------------------------------------------------------------

class Gate:
    """Holds the server's texture loading (its library's ``load``, in the worker thread) until released:
    ``entered`` is set when a load waits in it."""

    def __init__(self, serve: ServeThread):
        self.entered, self.released = threading.Event(), threading.Event()
        self._load = serve.server.library.load
        serve.server.library.load = self._gated  # type: ignore[method-assign,assignment]

    def _gated(self, request: object) -> object:
        if getattr(request, "yaml", None) is not None:
            self.entered.set()
            assert self.released.wait(REPLY_TIMEOUT_S)
        return self._load(request)  # type: ignore[arg-type]


BIG_YAML = unknown_keys_text(900 << 10).decode()
INLINE_YAML = "description: inline\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n"


def test_another_client_is_served_while_a_large_texture_is_parsed() -> None:
    """While one client's texture waits in its parse (a gate holds it), another's ping is answered and a third
    sets a texture: the parse holds neither the loop nor the texture lock. Released, the first is refused as
    superseded (the third's, requested later, was set first), and the renderer keeps the third's."""
    with ServeThread() as serve:
        gate = Gate(serve)
        with Client(serve.ws_url) as big, Client(serve.ws_url) as pinger, Client(serve.ws_url) as other:
            big.send({"type": "texture", "yaml": INLINE_YAML, "id": "big"})
            assert gate.entered.wait(REPLY_TIMEOUT_S)
            assert pinger.request({"type": "ping", "t": 2.5}, "pong")["t"] == 2.5
            assert other.request({"type": "texture", "name": "square_grating"}, "texture")["kind"] == "grating"
            gate.released.set()
            refused = big.expect("error")
            assert (refused["id"], refused["code"]) == ("big", "texture") and "requested after" in refused["message"]
            assert pinger.request({"type": "ping"}, "pong")["type"] == "pong"
        assert serve.renderer.texture.description != "inline" and serve.server.counters["textures_set"] == 1


def test_a_large_texture_of_unknown_keys_is_refused_in_one_capped_message_while_pings_go_on() -> None:
    with ServeThread() as serve:
        gate = Gate(serve)
        with Client(serve.ws_url) as big, Client(serve.ws_url) as pinger:
            big.send({"type": "texture", "yaml": BIG_YAML, "id": "big"})
            assert gate.entered.wait(REPLY_TIMEOUT_S)
            assert pinger.request({"type": "ping"}, "pong")["type"] == "pong"
            gate.released.set()
            refused = big.expect("error")
            lines = refused["message"].splitlines()
            assert refused["code"] == "texture" and len(lines) == MAX_LISTED_ERRORS + 1, lines[-2:]
            assert lines[0].endswith("unknown key (line 5)") and "more problems" in lines[-1]
            assert pinger.request({"type": "ping"}, "pong")["type"] == "pong"


def test_a_library_log_record_while_serving_is_one_counted_line(capfd: pytest.CaptureFixture[str]) -> None:
    """Should a library log (websockets on a handler that failed, asyncio on a callback, python-osc on a packet),
    stderr gets one line naming it, counted, never its traceback."""
    import logging

    with ServeThread() as serve:
        try:
            raise ValueError("boom")
        except ValueError:
            logging.getLogger("websockets.server").error("connection handler failed", exc_info=True)
        assert serve.server.counters["internal_logged"] == 1
    err = capfd.readouterr().err
    assert err.splitlines() == ["tpad-rt serve: websockets.server: connection handler failed: ValueError('boom') "
                                "(please report it)"], err


def parser_processes() -> set[int]:
    """PIDs of this process's children that are multiprocessing's spawned workers (the servers' parsers)."""
    found = set()
    for task in Path("/proc/self/task").iterdir():
        try:
            for pid in (task / "children").read_text().split():
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    found.add(int(pid))
        except FileNotFoundError:  # a thread or a child that has just ended
            pass
    return found


def test_a_parser_process_that_dies_costs_its_texture_one_line_and_the_next_is_read(
        capfd: pytest.CaptureFixture[str]) -> None:
    """The inline texture's reader is killed (as the kernel's OOM killer would) while it reads a large text:
    that texture is refused in one line naming what happened, nothing is printed, and new processes read the
    next texture."""
    import signal

    with ServeThread() as serve, Client(serve.ws_url) as client:
        others = parser_processes()  # earlier servers' (in this process), on their way out
        client.send({"type": "texture", "yaml": BIG_YAML, "id": "big"})
        while not (parsers := parser_processes() - others):  # it starts (pytest's timeout bounds the wait)
            time.sleep(0.01)
        for pid in parsers:
            os.kill(pid, signal.SIGKILL)
        refused = client.expect("error")
        assert (refused["id"], refused["code"]) == ("big", "texture") and "ended" in refused["message"], refused
        assert client.request({"type": "texture", "yaml": INLINE_YAML}, "texture")["source"] == "inline YAML"
        assert serve.server.counters.get("internal_logged", 0) == 0
    assert capfd.readouterr().err == ""
