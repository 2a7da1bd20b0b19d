"""The hostile load of the serve ping benchmark: large inline textures, or bad OSC bundles, for S seconds.

    python bench/latency/serve_load.py texture WS_URL SECONDS
    python bench/latency/serve_load.py osc UDP_PORT SECONDS RATE    # RATE datagrams a second; 0: as fast as it can

``texture``: connects (the ``websockets`` sync client) and sends, one after the other until
S seconds have passed, a ``texture`` message whose ``yaml`` is a grating padded to just
under the 1 MiB message limit with unknown keys (about 45,000), waiting for each refusal
(and at least MIN_SPACING_S between two sends).
``osc``: sends bad OSC datagrams in turn, of the kinds that hung or slowed the server (a
bundle element of negative size, one of size 0, 32 messages of an unknown address, a
type tag the server does not read, a datagram over 8 KiB), at RATE a second on the
monotonic clock's grid. Either prints ``READY`` once it has started loading, and one line
``RESULT {json}`` last: what it sent, and (texture) each refusal's seconds from send to reply.
"""

from __future__ import annotations

import json
import socket
import struct
import sys
import time

#: The texture message's target size (bytes): under tpad_rt.serve.protocol.MAX_MESSAGE_BYTES with the JSON around.
TEXTURE_MESSAGE_BYTES = 1_040_000
#: Least time from one texture message's send to the next (s): the server's 2 MiB a second of a client's
#: messages never drops one (a dropped message has no reply to wait for).
MIN_SPACING_S = 1.0
_HEAD = "description: x\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n"


def texture_message() -> str:
    """A ``texture`` message of about TEXTURE_MESSAGE_BYTES: a grating and unknown keys, one per line."""
    line = len(json.dumps("unknown_key_000000: 1\n")) - 2
    keys = (TEXTURE_MESSAGE_BYTES - 100) // line
    yaml = _HEAD + "".join(f"unknown_key_{index:06d}: 1\n" for index in range(keys))
    return json.dumps({"type": "texture", "yaml": yaml, "id": "load"})


def _message(address: str, tags: str, arguments: bytes) -> bytes:
    def padded(text: bytes) -> bytes:
        return text + b"\0" * (4 - len(text) % 4)

    return padded(address.encode()) + padded(b"," + tags.encode()) + arguments


def _bundle(*elements: bytes) -> bytes:
    return b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def bad_datagrams() -> list[bytes]:
    """The bad datagrams sent in turn (module docstring)."""
    ping = _message("/tpad/ping", "", b"")
    unknown = _message("/tpad/warp", "f", struct.pack(">f", 1.0))
    return [_bundle(ping)[:16] + struct.pack(">i", -4) + ping,
            _bundle(ping)[:16] + struct.pack(">i", 0) + ping,
            _bundle(*[unknown] * 32),
            _message("/tpad/finger", "b", struct.pack(">i", 4) + b"blob"),
            _bundle(*[_message("/tpad/texture", "s", b"x" * 4000 + b"\0" * 4)] * 3)]


def load_textures(url: str, seconds: float) -> dict[str, object]:
    from websockets.sync.client import connect

    message = texture_message()
    replies_s: list[float] = []
    with connect(url, max_size=None, open_timeout=60) as ws:
        json.loads(ws.recv())  # hello
        end = time.monotonic() + seconds
        print("READY", flush=True)
        while (sent := time.monotonic()) < end:
            ws.send(message)
            while json.loads(ws.recv(timeout=600)).get("id") != "load":
                pass
            replies_s.append(time.monotonic() - sent)
            time.sleep(max(0.0, sent + MIN_SPACING_S - time.monotonic()))
    return {"message_bytes": len(message), "sent": len(replies_s), "reply_s": replies_s}


def load_osc(port: int, seconds: float, rate_per_s: float) -> dict[str, object]:
    datagrams = bad_datagrams()
    sent = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        start = time.monotonic()
        print("READY", flush=True)
        while (now := time.monotonic()) < start + seconds:
            if rate_per_s > 0 and now < start + sent / rate_per_s:
                time.sleep(start + sent / rate_per_s - now)
                continue
            sock.sendto(datagrams[sent % len(datagrams)], ("127.0.0.1", port))
            sent += 1
    return {"sent": sent, "rate_per_s": sent / seconds, "datagram_bytes": [len(d) for d in datagrams]}


def main(argv: list[str]) -> None:
    kind, where, seconds = argv[0], argv[1], float(argv[2])
    result = load_textures(where, seconds) if kind == "texture" else load_osc(int(where), seconds, float(argv[3]))
    print("RESULT " + json.dumps(result), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
