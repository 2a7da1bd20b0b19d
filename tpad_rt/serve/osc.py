"""OSC over UDP for ``tpad-rt serve`` (python-osc's packet parser and message builder).

API map
-------
OscEndpoint.open(loop, host, port, handle, counters, clock) -> OscEndpoint
    listen on ``host:port`` (port 0: any free one, then ``.port``); ``close()``
ADDRESSES
    the OSC addresses read, and the request each becomes
message_count(data) -> int
    the messages in a datagram whose framing and type tags this server reads;
    ProtocolError ``bad_message`` otherwise

Each message becomes the request dict of the WebSocket API (docs/serve.md "OSC") and
goes through the same checks, limits and finger policy (``handle(sender, data)``); a
refusal is answered to the sender as ``/tpad/error code message``, a ``/tpad/ping`` as
``/tpad/pong t stream_t``. Bundles are taken apart and applied at once (their time
tags are not waited for: a sender cannot hold the loop with a time tag in the future).

Every datagram is budgeted before it is parsed: all senders together get
DATAGRAMS_PER_S datagrams, BYTES_PER_S bytes and MESSAGES_PER_S messages a second
(more are dropped unread and counted), and one datagram holds at most
MAX_DATAGRAM_BYTES bytes and MAX_DATAGRAM_MESSAGES messages in bundles at most
MAX_BUNDLE_DEPTH deep. Its framing and type tags are checked here
(:func:`message_count`) before python-osc reads it: python-osc logs a warning for an
element it cannot identify and loops forever on a negative element size. Replies (errors
and pongs) are budgeted too, REPLIES_PER_S server-wide, so a flood of bad datagrams
cannot become a flood of answers.
"""

from __future__ import annotations

import asyncio
import struct
from collections import Counter
from collections.abc import Awaitable, Callable
from typing import Any, cast

from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import build_msg
from pythonosc.osc_packet import OscPacket

from tpad_rt.clock import Clock
from tpad_rt.serve.core import TokenBucket
from tpad_rt.serve.protocol import ProtocolError

#: OSC address -> (request type, argument names in order; those after the first ``optional`` may be left out).
ADDRESSES: dict[str, tuple[str, tuple[str, ...], int]] = {
    "/tpad/finger": ("finger", ("x_mm", "y_mm", "force_n", "t"), 2),
    "/tpad/lift": ("lift", ("t",), 0),
    "/tpad/texture": ("texture", ("ref",), 1),
    "/tpad/ping": ("ping", ("t",), 0),
}
#: Most OSC datagrams handled at once (a flood beyond it is dropped and counted).
MAX_PENDING = 64
#: Largest datagram read (bytes); most messages in one, nested bundles' included; deepest bundle nesting.
MAX_DATAGRAM_BYTES, MAX_DATAGRAM_MESSAGES, MAX_BUNDLE_DEPTH = 8192, 32, 4
#: All senders together: datagrams, bytes and messages a second (the bursts: a tenth of a second's worth), and
#: replies a second (burst 100).
DATAGRAMS_PER_S, BYTES_PER_S, MESSAGES_PER_S, REPLIES_PER_S = 2000.0, float(1 << 20), 2000.0, 1000.0
#: The type tags read (a request's arguments are numbers and strings) and the bytes each takes (a string: 0,
#: its own length).
TYPE_TAG_BYTES = {"i": 4, "f": 4, "h": 8, "d": 8, "s": 0, "T": 0, "F": 0, "N": 0}
_BUNDLE = b"#bundle\0"

Handle = Callable[[tuple[str, int], dict[str, Any]], Awaitable[dict[str, Any] | None]]


def request_of(address: str, arguments: list[Any]) -> dict[str, Any]:
    """The request dict of an OSC message; ProtocolError for an unknown address or a wrong argument count."""
    if address not in ADDRESSES:
        raise ProtocolError("unknown_type", f"unknown OSC address {address[:80]!r} (the addresses: "
                            + ", ".join(ADDRESSES) + ")")
    kind, names, required = ADDRESSES[address]
    if not required <= len(arguments) <= len(names):
        count = f"{required}" if required == len(names) else f"{required} to {len(names)}"
        raise ProtocolError("bad_message", f"{address} takes {count} arguments ({', '.join(names)}), got "
                            f"{len(arguments)}", request=kind)
    data: dict[str, Any] = {"type": kind, **dict(zip(names, arguments))}
    if kind == "texture":  # a path has a folder or a .yaml suffix; anything else is a shipped name
        ref = data.pop("ref")
        looks_like_path = isinstance(ref, str) and ("/" in ref or ref.endswith((".yaml", ".yml")))
        data["path" if looks_like_path else "name"] = ref
    return data


def _bad(message: str) -> ProtocolError:
    return ProtocolError("bad_message", f"not an OSC packet this server reads: {message}")


def message_count(data: bytes) -> int:
    """How many messages ``data`` (one datagram) holds; ProtocolError ``bad_message`` saying what is wrong
    when it is larger than MAX_DATAGRAM_BYTES, holds more than MAX_DATAGRAM_MESSAGES, nests bundles deeper than
    MAX_BUNDLE_DEPTH, is not framed as OSC 1.0 says (4-byte alignment, element sizes within their bundle), or
    has a type tag outside TYPE_TAG_BYTES, arguments shorter than their tags, or text that is not UTF-8.
    One pass over the datagram (per element, and ``bytes.find`` and a decode per string)."""
    if len(data) > MAX_DATAGRAM_BYTES:
        raise _bad(f"{len(data):,} bytes; at most {MAX_DATAGRAM_BYTES:,}")
    count = 0
    stack = [(0, len(data), 0)]  # (start, end, depth) of the elements still to read
    while stack:
        start, end, depth = stack.pop()
        if (end - start) % 4 or end == start:
            raise _bad(f"an element of {end - start} bytes (OSC elements are a positive multiple of 4 bytes)")
        if data.startswith(_BUNDLE, start, end):
            if depth >= MAX_BUNDLE_DEPTH:
                raise _bad(f"bundles nested deeper than {MAX_BUNDLE_DEPTH}")
            index = start + 16  # the prefix and the time tag
            if index > end:
                raise _bad("a bundle without its time tag")
            while index < end:
                if index + 4 > end:
                    raise _bad("a bundle element's size is cut off")
                (size,) = struct.unpack_from(">i", data, index)
                if size <= 0 or size % 4 or index + 4 + size > end:
                    raise _bad(f"a bundle element of size {size} in {end - index - 4} bytes left")
                stack.append((index + 4, index + 4 + size, depth + 1))
                index += 4 + size
        else:
            _check_message(data, start, end)
            count += 1
            if count > MAX_DATAGRAM_MESSAGES:
                raise _bad(f"more than {MAX_DATAGRAM_MESSAGES} messages in one datagram")
    return count


def _check_message(data: bytes, start: int, end: int) -> None:
    """A message's address, type tags and argument sizes within ``data[start:end]``; ProtocolError otherwise."""
    if data[start:start + 1] != b"/":
        raise _bad("a message's address starts with '/'")
    index = _string_end(data, start, end, "the address")
    if index == end:
        return  # no type tag string: no arguments
    if data[index:index + 1] != b",":
        raise _bad("a message's type tags start with ','")
    tags_end = _string_end(data, index, end, "the type tag string")
    tags = data[index + 1:data.index(b"\0", index)].decode("latin-1")
    index = tags_end
    for tag in tags:
        size = TYPE_TAG_BYTES.get(tag)
        if size is None:
            raise _bad(f"type tag {tag!r} (read: {' '.join(TYPE_TAG_BYTES)})")
        index = _string_end(data, index, end, "a string argument") if tag == "s" else index + size
        if index > end:
            raise _bad(f"the arguments are shorter than their type tags {tags!r}")


def _string_end(data: bytes, start: int, end: int, what: str) -> int:
    """Where the NUL-terminated, 4-byte padded UTF-8 string at ``start`` ends; ProtocolError if it does not by
    ``end``, or is not UTF-8."""
    nul = data.find(b"\0", start, end)
    if nul < 0:
        raise _bad(f"{what} without its terminating NUL")
    try:
        data[start:nul].decode("utf-8")
    except UnicodeDecodeError:
        raise _bad(f"{what} is not UTF-8") from None
    return start + (nul - start) // 4 * 4 + 4


class OscEndpoint(asyncio.DatagramProtocol):
    """The UDP endpoint (module docstring): ``counters`` gets ``osc_datagrams``, ``osc_dropped`` (over a budget,
    unread), ``osc_replies_dropped`` and ``error_bad_message`` (a datagram it does not read); its budgets run on
    ``clock`` (the server's)."""

    def __init__(self, handle: Handle, counters: Counter[str], clock: Clock):
        self._handle = handle
        self._counters = counters
        self._clock = clock
        self._transport: asyncio.DatagramTransport | None = None
        self._pending: set[asyncio.Task[None]] = set()
        self._datagrams = TokenBucket(DATAGRAMS_PER_S, DATAGRAMS_PER_S / 10)
        self._bytes = TokenBucket(BYTES_PER_S, BYTES_PER_S / 10)
        self._messages = TokenBucket(MESSAGES_PER_S, MESSAGES_PER_S / 10)
        self._replies = TokenBucket(REPLIES_PER_S, 100.0)
        self.port = 0

    @classmethod
    async def open(cls, loop: asyncio.AbstractEventLoop, host: str, port: int, handle: Handle,
                   counters: Counter[str], clock: Clock) -> OscEndpoint:
        """Listen on ``host:port``; OSError when the port cannot be bound."""
        transport, endpoint = await loop.create_datagram_endpoint(lambda: cls(handle, counters, clock),
                                                                  local_addr=(host, port))
        endpoint.port = transport.get_extra_info("sockname")[1]
        return endpoint

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)  # asyncio's own is no subclass of it

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
        for task in self._pending:
            task.cancel()

    def datagram_received(self, data: bytes, sender: tuple[str, int]) -> None:
        """Budget, check, then parse and handle ``data`` (module docstring)."""
        now_s = self._clock.now_ns() * 1e-9
        self._counters["osc_datagrams"] += 1
        if len(self._pending) >= MAX_PENDING or not self._datagrams.take(1, now_s) or \
                not self._bytes.take(len(data), now_s):
            self._counters["osc_dropped"] += 1
            return
        try:
            count = message_count(data)
            if not self._messages.take(count, now_s):
                self._counters["osc_dropped"] += 1
                return
            messages = [timed.message for timed in OscPacket(data).messages]
        except ProtocolError as problem:
            self._counters["error_bad_message"] += 1
            self._reply(sender, "/tpad/error", [problem.code, problem.message])
            return
        except Exception:  # noqa: BLE001 - a packet message_count passed that python-osc still refuses
            self._counters["error_bad_message"] += 1
            self._reply(sender, "/tpad/error", ["bad_message", "not an OSC packet this server reads"])
            return
        task = asyncio.get_running_loop().create_task(self._serve(messages, sender))
        self._pending.add(task)
        task.add_done_callback(self._pending.discard)

    async def _serve(self, messages: list[OscMessage], sender: tuple[str, int]) -> None:
        for message in messages:
            try:
                reply = await self._handle(sender, request_of(message.address, list(message.params)))
            except ProtocolError as problem:
                self._reply(sender, "/tpad/error", [problem.code, problem.message])
                continue
            if reply is not None and reply.get("type") == "pong":
                self._reply(sender, "/tpad/pong", [reply["t"] if reply["t"] is not None else 0.0, reply["stream_t"]])

    def _reply(self, sender: tuple[str, int], address: str, values: list[Any]) -> None:
        """Send ``address values`` to ``sender``, within the server-wide reply budget (else counted)."""
        if not self._replies.take(1, self._clock.now_ns() * 1e-9):
            self._counters["osc_replies_dropped"] += 1
            return
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(build_msg(address, values).dgram, sender)
