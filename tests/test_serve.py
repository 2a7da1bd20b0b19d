"""``tpad-rt serve`` end to end: a real server process on loopback, real WebSocket and OSC clients.

What the renderer did is read from the server's telemetry (the blocks it rendered: the
finger it followed, the target friction, the drive) and, where the drive itself matters,
from its recording. Every wait is for a message (bounded by serve_process.REPLY_TIMEOUT_S,
a failure bound) and a finger is held where a telemetry message must show it (held_until);
nothing sleeps and hopes. The clients' budgets are judged exactly on a VirtualClock (the
server's clock, in a ServeThread); one realtime test (docs/testing.md) maps batches of
stamped samples as they arrive.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import build_msg
from websockets.exceptions import ConnectionClosedError, InvalidStatus

from cli_run import REPO, tpad_rt
from serve_process import REPLY_TIMEOUT_S, Client, Serve, ServeThread, osc_socket, stopped_by_signal_cleanly
from tpad_rt.cli.serve import _count
from tpad_rt.clock import VirtualClock
from tpad_rt.recording import read_recording
from tpad_rt.serve import protocol
from tpad_rt.texture import load_compiled

GRATING = REPO / "textures" / "grating.yaml"
PLATE_MM = (130.0, 60.0)


@pytest.fixture(scope="module")
def texture_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("textures")
    (folder / "coarse.yaml").write_text("description: coarse grating\nkind: grating\nwaveform: square\n"
                                        "period_mm: 20\nfriction: {low: 0.7, high: 1.0}\n")
    os.mkfifo(folder / "fifo.yaml")
    return folder


@pytest.fixture(scope="module")
def server(texture_dir: Path) -> Iterator[Serve]:
    with Serve(str(GRATING), "--output", "sim://", "--texture-dir", str(texture_dir)) as serve:
        yield serve
        out = stopped_by_signal_cleanly(serve)
        assert "served until Ctrl-C" in out, out


def swipe(client: Client, x_from_mm: float, x_to_mm: float, y_mm: float = 30.0, speed_mm_s: float = 100.0,
          stamped: float | None = 0.0) -> float:
    """Push a swipe, one sample per 2 ms of the client's clock (``stamped``: the client's clock offset, or
    None to send no times), paced by the clock; the last x (mm)."""
    steps = int(abs(x_to_mm - x_from_mm) / speed_mm_s / 0.002)
    for step in paced(steps + 1, 0.002):
        x_mm = x_from_mm + (x_to_mm - x_from_mm) * step / max(steps, 1)
        sample = {"type": "finger", "x_mm": x_mm, "y_mm": y_mm}
        if stamped is not None:
            sample["t"] = time.monotonic() + stamped
        client.send(sample)
    return x_to_mm


def paced(count: int, period_s: float) -> Iterator[int]:
    """0 .. count-1, each yielded when its time (``period_s`` apart on the monotonic clock) has come: a
    client's sample clock."""
    start = time.monotonic()
    for step in range(count):
        while time.monotonic() < start + step * period_s:
            pass
        yield step


def telemetry_until(client: Client, predicate: object) -> dict[str, object]:
    """The first telemetry message satisfying ``predicate``: for a state that lasts (a lifted finger, a silent
    drive); a finger's place is waited for with :func:`held_until`."""
    return client.expect("telemetry", predicate)  # type: ignore[arg-type]


def held_until(touch: Callable[[], None], watcher: Client,
               predicate: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    """Keep the finger where ``touch()`` puts it (one sample before each telemetry message) until a telemetry
    message of ``watcher`` satisfies ``predicate``; that message. A telemetry message is the newest block when
    it is sent, and a loaded machine sends it late: a finger left alone is lifted by the kernel's watchdog
    (50 ms) before a late message would have shown it."""
    while True:
        touch()
        message = watcher.expect("telemetry")
        if predicate(message):
            return message


def test_the_hello_states_the_protocol_device_texture_and_limits(server: Serve) -> None:
    with Client(server.ws_url) as client:
        hello = client.hello
    assert hello["protocol"] == protocol.PROTOCOL_VERSION and hello["server"].startswith("tpad-rt ")
    assert (hello["device"]["plate"]["length_mm"], hello["device"]["plate"]["width_mm"]) == pytest.approx(PLATE_MM)
    assert hello["device"]["max_voltage_v"] > 0 and hello["device"]["carrier_hz"] > 20000
    assert hello["device"]["output"] == "sim://"
    assert hello["texture"]["kind"] == "grating" and hello["texture"]["map"].startswith("/map.png")
    assert "grating" in hello["textures"]
    assert hello["limits"]["max_batch"] == protocol.MAX_BATCH
    assert hello["finger"] == {"held": False, "yours": False, "holder": None, "policy": hello["finger"]["policy"]}


def test_finger_samples_drive_the_renderer_along_the_texture_and_lift_ramps_it_down(server: Serve) -> None:
    grating = load_compiled(GRATING)
    with Client(server.ws_url) as client:
        client.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        last_x = swipe(client, 20.0, 60.0, stamped=1000.0)  # a client clock 1000 s ahead of the stream's
        assert client.expect("finger")["yours"] is True  # sent when the first sample took the finger
        seen = held_until(lambda: client.send({"type": "finger", "x_mm": last_x, "y_mm": 30.0,
                                               "t": time.monotonic() + 1000.0}),
                          client, lambda m: m["touching"] and abs(m["x_mm"] - last_x) < 2.0)
        assert seen["voltage_peak_v"] > 1.0
        assert seen["target_mu"] == pytest.approx(float(grating.evaluate(seen["x_mm"], seen["y_mm"], 1.0, 0.0)),
                                                  abs=1e-9)
        assert 0 < seen["achieved_mu"] <= 1.0
        client.send({"type": "lift"})
        assert client.expect("finger")["held"] is False
        off = telemetry_until(client, lambda m: not m["touching"] and m["voltage_v"] == 0.0)
        assert off["t"] > seen["t"]


@pytest.mark.realtime
def test_batches_of_stamped_samples_are_mapped_onto_the_stream_clock(server: Serve) -> None:
    """A client that sends 20 ms of samples at a time (2 ms apart, 100 mm/s), stamped by a clock 5000 s
    behind the stream's (times the renderer alone would refuse): the renderer follows them at their speed.
    Realtime: the batches are mapped as they arrive (ClockMap, tested with explicit times in
    tests/test_serve_protocol.py), and a machine that delays one past RESYNC_S maps it afresh."""
    with Client(server.ws_url) as client:
        client.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        start = time.monotonic()
        for batch in range(20):
            times = [start + 0.020 * batch + 0.002 * i for i in range(10)]
            while time.monotonic() < times[-1]:
                pass
            samples = [{"x_mm": 20.0 + 100.0 * (t - start), "y_mm": 20.0, "t": t - 5000.0} for t in times]
            client.send({"type": "fingers", "samples": samples})
        seen = telemetry_until(client, lambda m: m["touching"] and m["x_mm"] > 55.0)
        assert seen["y_mm"] == pytest.approx(20.0, abs=1e-6)
        assert seen["speed_mm_s"] == pytest.approx(100.0, rel=0.05)  # the samples' own spacing, not arrival's
        client.send({"type": "lift"})
        stats = client.request({"type": "stats"}, "stats")
    assert stats["server"].get("error_bad_sample", 0) == 0


def _corpus(texture_dir: Path) -> list[tuple[str | bytes, str]]:
    inline_outside = ("description: x\nkind: bitmap\nimage: /etc/hostname\nsize_mm: [10, 10]\n"
                      "friction: {low: 0.5, high: 1}\n")
    return [
        ("{not json", "bad_json"),
        ('{"type": "finger", "x_mm": NaN, "y_mm": 1}', "bad_json"),
        ("[" * 50_000, "bad_json"),
        ('{"type": "finger", "x_mm": "12", "y_mm": 1}', "bad_message"),
        ('{"type": "finger", "x_mm": true, "y_mm": 1}', "bad_message"),
        ('{"type": "finger", "x_mm": 1e999, "y_mm": 1}', "bad_message"),
        ('{"type": "subscribe", "rate_hz": "fast"}', "bad_message"),
        ('{"type": "teleport"}', "unknown_type"),
        ('{"kind": "finger"}', "bad_message"),
        (b"\x00\x01binary", "bad_message"),
        (json.dumps({"type": "finger", "x_mm": 1e300, "y_mm": 1}), "bad_sample"),
        (json.dumps({"type": "finger", "x_mm": 10, "y_mm": 10, "force_n": 1e6}), "bad_sample"),
        (json.dumps({"type": "finger", "x_mm": 10, "y_mm": 10, "force_n": -5e-324}), "bad_sample"),
        (json.dumps({"type": "texture", "path": "/etc/passwd"}), "forbidden_path"),
        (json.dumps({"type": "texture", "path": str(texture_dir / ".." / ".." / "etc" / "passwd")}), "forbidden_path"),
        (json.dumps({"type": "texture", "path": str(texture_dir / "fifo.yaml")}), "texture"),
        (json.dumps({"type": "texture", "name": "nope"}), "texture"),
        (json.dumps({"type": "texture", "yaml": "kind: grating\nperiod_mm: -1\n"}), "texture"),
        (json.dumps({"type": "texture", "yaml": inline_outside}), "texture"),
        ("x" * (protocol.MAX_MESSAGE_BYTES + 1), "too_large"),
        (json.dumps({"type": "texture", "yaml": "#" * (2 * protocol.MAX_MESSAGE_BYTES)}), "too_large"),
    ]


def test_a_corpus_of_bad_messages_each_gets_an_error_and_the_connection_keeps_serving(server: Serve,
                                                                                     texture_dir: Path) -> None:
    with Client(server.ws_url) as client:
        for index, (raw, code) in enumerate(_corpus(texture_dir)):
            client.send(raw)
            client.send({"type": "ping", "id": index})  # answered after the bad message's error
            error = client.expect("error")
            assert error["code"] == code, (index, raw[:80], error)
            assert error["message"] and "\n" not in error["message"].split("\n")[0]
            assert client.expect("pong")["id"] == index
        client.send({"type": "lift"})
        assert client.request({"type": "device"}, "device")["type"] == "device"


def test_a_flood_is_rate_limited_without_starving_another_client() -> None:
    """The server's budgets on a VirtualClock standing still: a burst of MESSAGES_BURST messages is taken, every
    one after it dropped (one notice, then one per LIMIT_NOTICE_S, each counting the drops), another client is
    served from its own budget, and the flooder's comes back at MESSAGES_PER_S, a message a millisecond."""
    from tpad_rt.serve.server import MESSAGES_BURST, MESSAGES_PER_S

    clock = VirtualClock()
    with ServeThread(clock) as serve, Client(serve.ws_url) as flooder, Client(serve.ws_url) as other:
        for _ in range(3000):  # lifts nobody needed: no reply, so only the limit answers
            flooder.send({"type": "lift"})
        first = flooder.expect("error", lambda m: m["code"] == "rate_limited")
        assert first["message"] == "too many messages (at most 1000 a second): 1 message dropped"
        # A request with an id always gets an answer: rate_limited naming it, with the drops since the notice.
        limited = flooder.request({"type": "ping", "t": 2.5}, "pong")
        assert (limited["type"], limited["code"]) == ("error", "rate_limited")
        assert limited["message"].endswith(f": {3000 - int(MESSAGES_BURST)} messages dropped")
        assert other.request({"type": "ping", "t": 1.5}, "pong")["t"] == 1.5
        clock.advance_by(round(1e9 / MESSAGES_PER_S))  # one message's worth of budget comes back
        pong = flooder.request({"type": "ping", "t": 2.5}, "pong")
        assert (pong["type"], pong["t"]) == ("pong", 2.5)
        assert flooder.request({"type": "ping"}, "pong")["code"] == "rate_limited"
        assert serve.server.counters["rate_limited"] == 3000 - MESSAGES_BURST + 2


def test_a_message_past_the_frame_limit_closes_that_connection_only(server: Serve) -> None:
    with Client(server.ws_url) as other, Client(server.ws_url) as client:
        client.send("x" * (protocol.MAX_FRAME_BYTES + 1))
        with pytest.raises(ConnectionClosedError) as closed:
            while True:
                client.receive()
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009
        assert other.request({"type": "ping"}, "pong")["type"] == "pong"


def test_one_client_owns_the_finger_until_it_lifts_or_leaves(server: Serve) -> None:
    with Client(server.ws_url) as first, Client(server.ws_url) as second:
        first.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        first.send({"type": "finger", "x_mm": 30.0, "y_mm": 30.0})
        assert first.expect("finger")["yours"] is True
        assert second.expect("finger")["holder"] == first.hello["client"]
        busy = second.request({"type": "finger", "x_mm": 90.0, "y_mm": 30.0}, "finger")
        assert busy["type"] == "error" and busy["code"] == "finger_busy"
        assert second.request({"type": "lift"}, "finger")["code"] == "finger_busy"
        first.send({"type": "lift"})
        assert second.expect("finger")["held"] is False
        second.send({"type": "finger", "x_mm": 90.0, "y_mm": 30.0})
        assert second.expect("finger", lambda m: m["held"])["yours"] is True
        held_until(lambda: second.send({"type": "finger", "x_mm": 90.0, "y_mm": 30.0}), first,
                   lambda m: m["touching"] and abs(m["x_mm"] - 90.0) < 1.0)
        for _ in range(5):
            second.send({"type": "finger", "x_mm": 90.0, "y_mm": 30.0})
        second.close()  # leaves holding it: the server lifts the finger
        assert first.expect("finger")["held"] is False
        telemetry_until(first, lambda m: not m["touching"] and m["voltage_v"] == 0.0)


def test_an_idle_holder_keeps_the_finger_for_its_idle_time_on_the_servers_clock_and_no_longer() -> None:
    from tpad_rt.serve.server import OWNER_IDLE_S

    clock = VirtualClock()
    with ServeThread(clock) as serve, Client(serve.ws_url) as first, Client(serve.ws_url) as second:
        first.send({"type": "finger", "x_mm": 30.0, "y_mm": 30.0})
        assert first.expect("finger")["yours"] is True
        clock.advance_by(round(OWNER_IDLE_S * 1e9))  # idle for exactly its idle time: still the holder's
        busy = second.request({"type": "finger", "x_mm": 90.0, "y_mm": 30.0}, "finger")
        assert (busy["type"], busy["code"]) == ("error", "finger_busy")
        clock.advance_by(1)
        second.send({"type": "finger", "x_mm": 90.0, "y_mm": 30.0})
        assert second.expect("finger", lambda m: m["held"] and m["yours"])["holder"] == second.hello["client"]
        assert first.expect("finger", lambda m: m["held"])["yours"] is False


def test_textures_by_name_path_and_yaml_reach_every_client_and_the_renderer(server: Serve, texture_dir: Path) -> None:
    with Client(server.ws_url) as setter, Client(server.ws_url) as watcher:
        watcher.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        maps = []
        for ref, kind, description in [({"name": "bumps_grid"}, "bumps", None),
                                       ({"path": str(texture_dir / "coarse.yaml")}, "grating", "coarse grating"),
                                       ({"yaml": "description: even\nkind: grating\nperiod_mm: 5\n"
                                                 "friction: {low: 0.6, high: 0.6}\n"}, "grating", "even")]:
            reply = setter.request({"type": "texture", **ref}, "texture")
            assert reply["type"] == "texture" and reply["kind"] == kind, reply
            assert description is None or reply["description"] == description
            assert watcher.expect("texture")["map"] == reply["map"]
            maps.append(reply["map"])
        assert len(set(maps)) == 3
        seen = held_until(lambda: setter.send({"type": "finger", "x_mm": 65.0, "y_mm": 30.0}), watcher,
                          lambda m: m["touching"] and m["target_mu"] == pytest.approx(0.6))
        assert seen["target_mu"] == pytest.approx(0.6)
        setter.send({"type": "lift"})
        setter.request({"type": "texture", "name": "grating"}, "texture")


def test_the_page_its_map_and_nothing_else_are_served(server: Serve) -> None:
    with urllib.request.urlopen(server.http_url + "/") as page:
        html = page.read().decode()
        assert page.headers["Content-Type"].startswith("text/html")
        assert "default-src 'self'" in page.headers["Content-Security-Policy"]
    assert '<script type="module" src="page.js">' in html
    with urllib.request.urlopen(server.http_url + "/page.js") as script:
        assert "PROTOCOL_VERSION = 1" in script.read().decode()
    with Client(server.ws_url) as client:
        map_url = client.hello["texture"]["map"]
    with urllib.request.urlopen(server.http_url + map_url) as image:
        picture = Image.open(image)
        width, height = picture.size
    assert width / height == pytest.approx(PLATE_MM[0] / PLATE_MM[1], rel=0.02) and width >= 260
    for path in ("/nope", "/../../etc/passwd", "/static/page.js"):
        with pytest.raises(urllib.error.HTTPError) as missing:
            urllib.request.urlopen(server.http_url + path)
        assert missing.value.code == 404


def test_a_page_of_another_origin_may_not_open_the_websocket(server: Serve) -> None:
    with pytest.raises(InvalidStatus) as refused:
        Client(server.ws_url, origin="http://evil.example")  # type: ignore[arg-type]
    assert refused.value.response.status_code == 403
    with Client(server.ws_url, origin=f"http://localhost:{server.port}") as own:  # type: ignore[arg-type]
        assert own.hello["type"] == "hello"


def _osc(sock: socket.socket, port: int, address: str, *values: object) -> None:
    sock.sendto(build_msg(address, list(values)).dgram, ("127.0.0.1", port))


def _osc_reply(sock: socket.socket) -> OscMessage:
    return OscMessage(sock.recv(65536))


def test_osc_takes_finger_samples_and_textures_and_answers_bad_messages(server: Serve) -> None:
    assert server.osc_port is not None
    with Client(server.ws_url) as watcher, osc_socket() as sock:
        watcher.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        _osc(sock, server.osc_port, "/tpad/texture", "coarse.yaml")
        assert _osc_reply(sock).params[0] == "forbidden_path"  # a path: relative to the server's folder
        _osc(sock, server.osc_port, "/tpad/texture", "square_grating")
        assert watcher.expect("texture")["kind"] == "grating"
        for step in paced(200, 0.002):  # 100 mm/s
            _osc(sock, server.osc_port, "/tpad/finger", 40.0 + 0.2 * step, 25.0)
        held_until(lambda: _osc(sock, server.osc_port, "/tpad/finger", 79.8, 25.0), watcher,  # type: ignore[arg-type]
                   lambda m: m["touching"] and abs(m["x_mm"] - 79.8) < 2.0)
        _osc(sock, server.osc_port, "/tpad/lift")
        telemetry_until(watcher, lambda m: not m["touching"])
        for address, values, code in [("/tpad/finger", ["a", 1.0], "bad_message"), ("/tpad/finger", [1.0], "bad_message"),
                                      ("/tpad/finger", [float("nan"), 1.0], "bad_message"),
                                      ("/tpad/finger", [1e30, 1.0], "bad_sample"),
                                      ("/tpad/finger", [float("inf"), 1.0], "bad_message"), ("/tpad/warp", [], "unknown_type")]:
            _osc(sock, server.osc_port, address, *values)
            reply = _osc_reply(sock)
            assert (reply.address, reply.params[0]) == ("/tpad/error", code), (address, values, reply.params)
        sock.sendto(b"\xff garbage", ("127.0.0.1", server.osc_port))
        assert _osc_reply(sock).params[0] == "bad_message"
        _osc(sock, server.osc_port, "/tpad/ping", 7.0)
        pong = _osc_reply(sock)
        assert pong.address == "/tpad/pong" and pong.params[0] == 7.0
        _osc(sock, server.osc_port, "/tpad/texture", "grating")
        watcher.expect("texture")


def test_ctrl_c_lifts_and_ramps_the_drive_to_zero_in_the_recording(tmp_path: Path) -> None:
    record = tmp_path / "serve.npz"
    serve = Serve(str(GRATING), "--output", "sim://", "--record", str(record), "--no-osc",
                  port_args=("--port", "0"))
    with serve, Client(serve.ws_url) as client:
        client.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        swipe(client, 20.0, 50.0, stamped=None)
        telemetry_until(client, lambda m: m["touching"] and m["voltage_v"] > 1.0)
        for _ in range(10):  # still touching when the signal comes
            client.send({"type": "finger", "x_mm": 50.0, "y_mm": 30.0})
        client.request({"type": "ping"}, "pong")
        out = stopped_by_signal_cleanly(serve)
    assert "served until Ctrl-C" in out and f"wrote {record}" in out
    recording = read_recording(record)
    block = recording.metadata["block_frames"]
    peaks = np.abs(recording.drive[:len(recording.drive) // block * block]).reshape(-1, block).max(axis=1)
    last_driven = int(np.flatnonzero(peaks > 0.0)[-1])
    assert last_driven < len(peaks) - 1 and np.all(peaks[last_driven + 1:] == 0.0)  # it ended at 0
    ramp_blocks = recording.metadata["render_options"]["ramp_ms"] * 1e-3 * recording.fs_hz / block
    plateau = peaks[max(0, last_driven - int(8 * ramp_blocks)):last_driven - int(2 * ramp_blocks)].max()
    assert plateau > 0.1  # the finger was driving it when the signal came
    fading = np.flatnonzero(peaks[:last_driven + 1] >= 0.9 * plateau)[-1]
    assert last_driven - fading >= 0.8 * ramp_blocks  # faded over the ramp, not cut


@pytest.mark.parametrize(("args", "message"), [
    (["--host", "0.0.0.0"], "listens beyond this machine; add --allow-remote"),
    (["--token", "short"], "--token: must be 8-256 characters"),
    (["--texture-dir", "/nonexistent/dir"], "not a folder"),
    (["--allow-origin", "evil.example"], "an origin is scheme://host[:port]"),
    (["--port", "70000"], "must be a whole number in [0, 65535]"),
    (["nope.yaml"], "nope.yaml"),
    (["--record", "x.wav"], "--record: must end in .npz"),
])
def test_bad_flags_end_in_one_line(args: list[str], message: str) -> None:
    tpad_rt("serve", "--output", "null://", *args).assert_one_line_error(message)


def test_a_port_in_use_is_one_clear_line(server: Serve) -> None:
    run = tpad_rt("serve", "--output", "null://", "--port", str(server.port), "--no-osc")
    run.assert_one_line_error("cannot listen")
    assert "Address already in use" in run.stderr


def test_beyond_loopback_every_client_needs_the_token_and_sigterm_stops_it() -> None:
    serve = Serve("--output", "null://", "--host", "0.0.0.0", "--allow-remote", "--token", "s3cret-token",
                  "--no-osc", port_args=("--port", "0"))
    with serve:
        assert any("token: s3cret-token" in line for line in serve.stdout + [serve._lines.get(timeout=REPLY_TIMEOUT_S) or ""])
        for url in (serve.ws_url, serve.ws_url + "?token=wrong-token"):
            with pytest.raises(InvalidStatus) as refused:
                Client(url)
            assert refused.value.response.status_code == 401
        with Client(serve.ws_url + "?token=s3cret-token") as client:
            assert client.hello["type"] == "hello"
        with Client(serve.ws_url, additional_headers={"Authorization": "Bearer s3cret-token"}) as client:
            assert client.hello["type"] == "hello"
        assert "served until SIGTERM" in stopped_by_signal_cleanly(serve, signal.SIGTERM)  # stops as Ctrl-C does


def test_connections_beyond_the_limit_are_refused_until_one_leaves(server: Serve) -> None:
    from tpad_rt.serve.server import MAX_CLIENTS

    clients = [Client(server.ws_url) for _ in range(MAX_CLIENTS)]
    try:
        with pytest.raises(InvalidStatus) as refused:
            Client(server.ws_url)
        assert refused.value.response.status_code == 503
        clients.pop().close()
        deadline = time.monotonic() + REPLY_TIMEOUT_S  # a failure bound
        while True:  # the server lets the next one in once it has seen the close (its handler ended)
            try:
                latecomer = Client(server.ws_url)
                break
            except InvalidStatus as full:
                assert full.response.status_code == 503 and time.monotonic() < deadline
        clients.append(latecomer)
        assert latecomer.request({"type": "ping"}, "pong")["type"] == "pong"
    finally:
        for client in clients:
            client.close()


def test_device_and_stats_requests_have_their_own_budget() -> None:
    """On a VirtualClock standing still: a burst of HEAVY_PER_S device and stats requests, then each refused
    until the clock gives one back (1 / HEAVY_PER_S s later); other requests are not held."""
    from tpad_rt.serve.server import HEAVY_PER_S

    clock = VirtualClock()
    with ServeThread(clock) as serve, Client(serve.ws_url) as client:
        kinds = [client.request({"type": kind}, kind)["type"] for kind in ("stats", "device") * 20]
        assert kinds == ["stats", "device"] * 10 + ["error"] * 20
        assert client.request({"type": "ping"}, "pong")["type"] == "pong"
        clock.advance_by(round(1e9 / HEAVY_PER_S) - 1)
        assert client.request({"type": "stats"}, "stats")["code"] == "rate_limited"
        clock.advance_by(1)
        assert client.request({"type": "stats"}, "stats")["type"] == "stats"
        assert serve.server.counters["rate_limited"] == 21


def test_the_summary_counts_in_the_singular_for_one() -> None:
    """``1 WebSocket connection``, not ``1 WebSocket connections``: the summary's counts agree with their nouns."""
    assert [_count(number, "WebSocket connection") for number in (0, 1, 2)] == [
        "0 WebSocket connections", "1 WebSocket connection", "2 WebSocket connections"]
