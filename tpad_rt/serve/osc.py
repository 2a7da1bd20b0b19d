"""OSC over UDP for ``tpad-rt serve`` (python-osc's packet parser and message builder).

API map
-------
OscEndpoint.open(loop, host, port, handle) -> OscEndpoint
    listen on ``host:port`` (port 0: any free one, then ``.port``); ``close()``
ADDRESSES
    the OSC addresses read, and the request each becomes

Each message becomes the request dict of the WebSocket API (docs/serve.md "OSC") and
goes through the same checks, limits and finger policy (``handle(sender, data)``); a
refusal is answered to the sender as ``/tpad/error code message``, a ``/tpad/ping`` as
``/tpad/pong t stream_t``. Bundles are taken apart and applied at once (their time
tags are not waited for: a sender cannot hold the loop with a time tag in the future).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any, cast

from pythonosc.osc_message_builder import build_msg
from pythonosc.osc_packet import OscPacket

from tpad_rt.serve.protocol import ProtocolError

#: OSC address -> (request type, argument names in order; those after the first ``optional`` may be left out).
ADDRESSES: dict[str, tuple[str, tuple[str, ...], int]] = {
    "/tpad/finger": ("finger", ("x_mm", "y_mm", "force_n", "t"), 2),
    "/tpad/lift": ("lift", ("t",), 0),
    "/tpad/texture": ("texture", ("ref",), 1),
    "/tpad/ping": ("ping", ("t",), 0),
}
#: Most OSC messages handled at once (a flood beyond it is dropped, counted by the kernel's UDP buffer).
MAX_PENDING = 64

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


class OscEndpoint(asyncio.DatagramProtocol):
    """The UDP endpoint (module docstring)."""

    def __init__(self, handle: Handle):
        self._handle = handle
        self._transport: asyncio.DatagramTransport | None = None
        self._pending: set[asyncio.Task[None]] = set()
        self.port = 0

    @classmethod
    async def open(cls, loop: asyncio.AbstractEventLoop, host: str, port: int, handle: Handle) -> OscEndpoint:
        """Listen on ``host:port``; OSError when the port cannot be bound."""
        transport, endpoint = await loop.create_datagram_endpoint(lambda: cls(handle), local_addr=(host, port))
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
        if len(self._pending) >= MAX_PENDING:
            return
        task = asyncio.get_running_loop().create_task(self._serve(data, sender))
        self._pending.add(task)
        task.add_done_callback(self._pending.discard)

    async def _serve(self, data: bytes, sender: tuple[str, int]) -> None:
        try:
            messages = [timed.message for timed in OscPacket(data).messages]
        except Exception:  # noqa: BLE001 - python-osc raises ParseError, and others for hostile bundles
            self._reply(sender, "/tpad/error", ["bad_message", "not an OSC packet this server reads"])
            return
        for message in messages:
            try:
                reply = await self._handle(sender, request_of(message.address, list(message.params)))
            except ProtocolError as problem:
                self._reply(sender, "/tpad/error", [problem.code, problem.message])
                continue
            if reply is not None and reply.get("type") == "pong":
                self._reply(sender, "/tpad/pong", [reply["t"] if reply["t"] is not None else 0.0, reply["stream_t"]])

    def _reply(self, sender: tuple[str, int], address: str, values: list[Any]) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(build_msg(address, values).dgram, sender)
