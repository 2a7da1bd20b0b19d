"""The JSON messages of ``tpad-rt serve`` (docs/serve.md is the contract): limits, models and parsing.

API map
-------
PROTOCOL_VERSION
    the version the server's ``hello`` states (an app checks it before anything else)
MAX_MESSAGE_BYTES, MAX_FRAME_BYTES, MAX_BATCH, MAX_ID_CHARS, MAX_SUBSCRIBE_HZ, MAX_CLIENT_T_S
    a message's largest size (larger ones up to MAX_FRAME_BYTES get an error reply;
    past it the connection closes with 1009), the most samples in one ``fingers``,
    the longest request id, the fastest telemetry subscription, the largest client
    time (s, either sign)
parse(raw) -> Request
    one client message (text) checked and typed; ProtocolError (its ``code``, the
    message, the request's ``id`` when it had one) for anything else
validate(data) -> Request
    the same for a message already decoded (an OSC message's arguments)
Finger, Fingers, Lift, SetTexture, DeviceInfo, Subscribe, Stats, Ping
    the requests (pydantic models: strict types, finite numbers, no unknown keys)
error(code, message, request_id=None, request=None) -> dict
    an ``error`` reply

Numbers must be JSON numbers (``true`` is not one, nor ``"1.5"``); ``NaN`` and
``Infinity`` (which Python's json would accept) are refused, as are numbers that do not
fit a float (``1e999``). Values within range but physically wrong (a finger two plate
lengths away) are the renderer's to refuse (its SampleError becomes ``bad_sample``).
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from tpad_rt.config.messages import did_you_mean

PROTOCOL_VERSION = 1
#: The largest message the server reads (bytes); up to MAX_FRAME_BYTES one gets a ``too_large`` reply.
MAX_MESSAGE_BYTES = 1 << 20
#: The largest WebSocket message at all: past it the connection closes with code 1009 (message too big).
MAX_FRAME_BYTES = 4 << 20
#: Most samples in one ``fingers`` message.
MAX_BATCH = 512
#: Longest request ``id`` string (a number id is any integer within 2**53).
MAX_ID_CHARS = 64
#: Fastest telemetry subscription (Hz) and the slowest (a rate of 0 ends one).
MAX_SUBSCRIBE_HZ = 100.0
MIN_SUBSCRIBE_HZ = 0.1
#: Largest client time (s, either sign): 317 years, beyond any clock's seconds (the Unix epoch's included), so
#: mapping one onto the stream clock cannot overflow.
MAX_CLIENT_T_S = 1e10
#: Longest texture reference (a name or path), characters.
MAX_PATH_CHARS = 4096

#: Error codes (docs/serve.md "Errors").
ERROR_CODES = ("bad_json", "bad_message", "unknown_type", "too_large", "rate_limited", "finger_busy",
               "bad_sample", "texture", "forbidden_path", "internal")

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
ClientTime = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_CLIENT_T_S, le=MAX_CLIENT_T_S)]
RequestId = Union[Annotated[int, Field(strict=True, ge=-(2**53), le=2**53)],
                  Annotated[str, Field(strict=True, max_length=MAX_ID_CHARS)]]


class _Message(BaseModel):
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)

    id: RequestId | None = None


class Sample(BaseModel):
    """One finger sample: plate position (mm), force (N; None: the server's default), the client's time (s;
    None: when it arrives)."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)

    x_mm: Number
    y_mm: Number
    force_n: Number | None = None
    t: ClientTime | None = None


class Finger(_Message, Sample):
    """``finger``: one sample (the finger touches, or keeps touching)."""

    type: Literal["finger"]


class Fingers(_Message):
    """``fingers``: 1 to MAX_BATCH samples, oldest first."""

    type: Literal["fingers"]
    samples: Annotated[list[Sample], Field(min_length=1, max_length=MAX_BATCH)]


class Lift(_Message):
    """``lift``: the finger leaves the plate (at the client's time ``t``; None: when it arrives)."""

    type: Literal["lift"]
    t: ClientTime | None = None


class SetTexture(_Message):
    """``texture``: render a shipped texture by ``name``, a file by ``path`` (within the server's texture
    folders), or a texture file's text ``yaml``; exactly one of them."""

    type: Literal["texture"]
    name: Annotated[str, Field(strict=True, min_length=1, max_length=MAX_PATH_CHARS)] | None = None
    path: Annotated[str, Field(strict=True, min_length=1, max_length=MAX_PATH_CHARS)] | None = None
    yaml: Annotated[str, Field(strict=True, min_length=1)] | None = None

    def model_post_init(self, context: Any) -> None:
        given = [key for key in ("name", "path", "yaml") if getattr(self, key) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of name, path or yaml (got {', '.join(given) or 'none'})")


class DeviceInfo(_Message):
    """``device``: the device's plate, limits and carrier."""

    type: Literal["device"]


class Subscribe(_Message):
    """``subscribe``: telemetry ``rate_hz`` times a second (MIN_SUBSCRIBE_HZ to MAX_SUBSCRIBE_HZ; 0 ends it)."""

    type: Literal["subscribe"]
    rate_hz: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0.0, le=MAX_SUBSCRIBE_HZ)]


class Stats(_Message):
    """``stats``: the renderer's counters and distributions."""

    type: Literal["stats"]


class Ping(_Message):
    """``ping``: answered at once with ``pong`` (its ``t`` echoed, the server's stream time)."""

    type: Literal["ping"]
    t: Number | None = None


Request = Union[Finger, Fingers, Lift, SetTexture, DeviceInfo, Subscribe, Stats, Ping]
_REQUESTS: TypeAdapter[Request] = TypeAdapter(Annotated[Request, Field(discriminator="type")])
#: The request types by name, in docs/serve.md's order.
REQUEST_TYPES = ("finger", "fingers", "lift", "texture", "device", "subscribe", "stats", "ping")


class ProtocolError(Exception):
    """A message the server refuses: ``code`` (ERROR_CODES), a one-line message, and the request's ``id``
    and ``type`` when they could be read."""

    def __init__(self, code: str, message: str, request_id: Any = None, request: str | None = None):
        super().__init__(message)
        self.code, self.message, self.request_id, self.request = code, message, request_id, request

    def reply(self) -> dict[str, Any]:
        """The ``error`` message for it."""
        return error(self.code, self.message, self.request_id, self.request)


def error(code: str, message: str, request_id: Any = None, request: str | None = None) -> dict[str, Any]:
    """An ``error`` reply: ``{"type": "error", "code", "message"}`` with the request's ``id`` and ``request``
    type when known."""
    reply: dict[str, Any] = {"type": "error", "code": code, "message": message}
    if request_id is not None:
        reply["id"] = request_id
    if request is not None:
        reply["request"] = request
    return reply


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number here (JSON has no {name}; send finite numbers)")


def _decoded(raw: str) -> Any:
    """The JSON value of ``raw``; ProtocolError bad_json (with where it broke) otherwise."""
    try:
        return json.loads(raw, parse_constant=_no_constant)
    except json.JSONDecodeError as problem:
        raise ProtocolError("bad_json", f"not JSON: {problem.msg} at line {problem.lineno} column {problem.colno}") \
            from None
    except RecursionError:
        raise ProtocolError("bad_json", "not JSON this server reads: nested too deeply") from None
    except ValueError as problem:  # NaN/Infinity, or an integer of more than 4300 digits
        reason = str(problem) if "JSON has no" in str(problem) else "an integer with too many digits"
        raise ProtocolError("bad_json", f"not JSON this server reads: {reason}") from None


def _shown(value: Any) -> str:
    """A short rendering of a bad value for an error message."""
    text = json.dumps(value) if isinstance(value, (int, float, str, bool, type(None))) else type(value).__name__
    if isinstance(value, float) and not math.isfinite(value):
        text = str(value)
    return text if len(text) <= 40 else text[:37] + "..."


def parse(raw: str | bytes) -> Request:
    """One client message (a WebSocket text message) as a Request; ProtocolError for anything else:
    bytes (a binary message), bad JSON, not an object, an unknown ``type``, or fields that do not fit it."""
    if isinstance(raw, (bytes, bytearray, memoryview)):
        raise ProtocolError("bad_message", "binary messages are not read: send JSON as text messages")
    return validate(_decoded(raw))


def validate(data: Any) -> Request:
    """A decoded message (JSON's values, or an OSC message's arguments put in one) as a Request;
    ProtocolError as :func:`parse`."""
    if not isinstance(data, dict):
        raise ProtocolError("bad_message", f"a message is a JSON object with a 'type', got {type(data).__name__}")
    request_id = data.get("id") if isinstance(data.get("id"), (int, str)) and not isinstance(data.get("id"), bool) \
        else None
    kind = data.get("type")
    if not isinstance(kind, str):
        raise ProtocolError("bad_message", "a message needs a 'type' string (one of " + ", ".join(REQUEST_TYPES) + ")",
                            request_id)
    if kind not in REQUEST_TYPES:
        raise ProtocolError("unknown_type", f"unknown message type {_shown(kind)} (the types: "
                            f"{', '.join(REQUEST_TYPES)}){did_you_mean(kind, list(REQUEST_TYPES))}", request_id)
    try:
        return _REQUESTS.validate_python(data)
    except ValidationError as problem:
        details = problem.errors(include_url=False)
        first = details[0]
        where = ".".join(str(part) for part in first["loc"][1:]) or kind  # loc[0] is the union's tag
        reason = first["msg"].removeprefix("Value error, ")
        reason = reason[0].lower() + reason[1:]
        shown = first["type"] != "missing" and "input" in first and not isinstance(first["input"], dict)
        given = f", got {_shown(first['input'])}" if shown else ""
        more = f" (and {len(details) - 1} more)" if len(details) > 1 else ""
        raise ProtocolError("bad_message", f"{where}: {reason}{given}{more}", request_id, kind) from None
