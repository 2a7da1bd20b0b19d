"""tpad-rt serve's decisions apart from the network: message parsing, the clock map, the rate limit, the
finger's owner and the texture folders (tpad_rt.serve.protocol, tpad_rt.serve.core)."""

from __future__ import annotations

import json
import logging
import os
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tpad_rt.serve import protocol
from tpad_rt.serve.core import RESYNC_S, ClockMap, FingerOwner, TextureLibrary, TokenBucket
from tpad_rt.serve.protocol import ProtocolError, SetTexture
from tpad_rt.shipped import TEXTURES_DIR

FINGER = {"type": "finger", "x_mm": 20.0, "y_mm": 30.0}

#: (message, the error code it must get, a fragment of the message).
BAD_MESSAGES = [
    ("{", "bad_json", "not JSON"),
    ("", "bad_json", "not JSON"),
    ('{"type": "finger", "x_mm": NaN, "y_mm": 1}', "bad_json", "NaN"),
    ('{"type": "finger", "x_mm": Infinity, "y_mm": 1}', "bad_json", "Infinity"),
    ('{"type": "finger", "x_mm": -Infinity, "y_mm": 1}', "bad_json", "Infinity"),
    ('{"type": "finger", "x_mm": 1e999, "y_mm": 1}', "bad_message", "finite"),
    ('{"type": "ping", "id": ' + "9" * 5000 + "}", "bad_json", "digits"),
    ("[" * 100_000 + "]" * 100_000, "bad_json", "nested"),
    ("5", "bad_message", "JSON object"),
    ("[]", "bad_message", "JSON object"),
    ('"finger"', "bad_message", "JSON object"),
    ("{}", "bad_message", "'type'"),
    ('{"type": 3}', "bad_message", "'type'"),
    ('{"type": "fnger"}', "unknown_type", "did you mean 'finger'"),
    ('{"type": "__proto__"}', "unknown_type", "the types"),
    (json.dumps({**FINGER, "x_mm": "20"}), "bad_message", "x_mm"),
    (json.dumps({**FINGER, "x_mm": True}), "bad_message", "x_mm"),
    (json.dumps({**FINGER, "x_mm": None}), "bad_message", "x_mm"),
    (json.dumps({**FINGER, "x_mm": [1]}), "bad_message", "x_mm"),
    (json.dumps({**FINGER, "x_mm": {"a": 1}}), "bad_message", "x_mm"),
    (json.dumps({"type": "finger", "x_mm": 1.0}), "bad_message", "y_mm"),
    (json.dumps({**FINGER, "pressure": 1}), "bad_message", "pressure"),
    (json.dumps({**FINGER, "id": 1.5}), "bad_message", "id"),
    (json.dumps({**FINGER, "id": "x" * 65}), "bad_message", "id"),
    (json.dumps({**FINGER, "id": 2**60}), "bad_message", "id"),
    (json.dumps({"type": "fingers", "samples": []}), "bad_message", "samples"),
    (json.dumps({"type": "fingers", "samples": [{"x_mm": 1, "y_mm": 1}] * (protocol.MAX_BATCH + 1)}),
     "bad_message", "samples"),
    (json.dumps({"type": "fingers", "samples": [{"x_mm": 1, "y_mm": 1}, {"x_mm": "a", "y_mm": 1}]}),
     "bad_message", "samples.1.x_mm"),
    (json.dumps({"type": "fingers", "samples": "everywhere"}), "bad_message", "samples"),
    (json.dumps({"type": "texture"}), "bad_message", "exactly one"),
    (json.dumps({"type": "texture", "name": "grating", "yaml": "kind: grating"}), "bad_message", "exactly one"),
    (json.dumps({"type": "texture", "name": ""}), "bad_message", "name"),
    (json.dumps({"type": "texture", "path": "p" * (protocol.MAX_PATH_CHARS + 1)}), "bad_message", "path"),
    (json.dumps({"type": "subscribe", "rate_hz": 1e9}), "bad_message", "rate_hz"),
    (json.dumps({"type": "subscribe", "rate_hz": -1}), "bad_message", "rate_hz"),
    (json.dumps({"type": "subscribe"}), "bad_message", "rate_hz"),
    (json.dumps({"type": "lift", "t": "now"}), "bad_message", "t"),
    (json.dumps({"type": "lift", "t": 1e308}), "bad_message", "t: input should be less than or equal to 1"),
    (json.dumps({**FINGER, "t": -1.0000001e10}), "bad_message", "t: input should be greater than or equal to -1"),
    (b'{"type": "ping"}', "bad_message", "binary"),
]


@pytest.mark.parametrize(("raw", "code", "fragment"), BAD_MESSAGES,
                         ids=[f"{index}-{code}" for index, (_, code, _) in enumerate(BAD_MESSAGES)])
def test_every_bad_message_is_refused_with_its_code_and_a_clear_line(raw: str | bytes, code: str,
                                                                      fragment: str) -> None:
    with pytest.raises(ProtocolError) as refused:
        protocol.parse(raw)
    assert refused.value.code == code and code in protocol.ERROR_CODES
    assert fragment in refused.value.message, refused.value.message
    assert "\n" not in refused.value.message and len(refused.value.message) < 400
    reply = refused.value.reply()
    assert reply["type"] == "error" and reply["code"] == code


def test_the_reply_names_the_request_and_echoes_its_id() -> None:
    with pytest.raises(ProtocolError) as refused:
        protocol.parse(json.dumps({**FINGER, "x_mm": "a", "id": "move-7"}))
    assert refused.value.reply() == {"type": "error", "code": "bad_message", "id": "move-7", "request": "finger",
                                     "message": refused.value.message}


def test_good_messages_parse_into_their_requests() -> None:
    finger = protocol.parse(json.dumps({**FINGER, "force_n": 1, "t": 12.5, "id": 3}))
    assert isinstance(finger, protocol.Finger) and (finger.x_mm, finger.force_n, finger.t, finger.id) == \
        (20.0, 1.0, 12.5, 3)
    batch = protocol.parse(json.dumps({"type": "fingers", "samples": [{"x_mm": 1, "y_mm": 2, "t": 0.5}] * 3}))
    assert isinstance(batch, protocol.Fingers) and len(batch.samples) == 3
    for kind in ("device", "stats", "ping", "lift"):
        assert protocol.parse(json.dumps({"type": kind})).type == kind
    texture = protocol.parse(json.dumps({"type": "texture", "yaml": "kind: grating"}))
    assert isinstance(texture, SetTexture) and texture.yaml == "kind: grating"
    assert protocol.parse('{"type": "subscribe", "rate_hz": 0}').rate_hz == 0.0  # type: ignore[union-attr]


@settings(max_examples=200, deadline=None)
@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=20),
                    lambda children: st.lists(children, max_size=4) | st.dictionaries(
                        st.sampled_from(["type", "x_mm", "y_mm", "t", "id", "samples", "name", "rate_hz"]) | st.text(
                            max_size=5), children, max_size=5), max_leaves=12))
def test_any_json_value_is_a_request_or_a_protocol_error(value: object) -> None:
    """Random JSON (types mixed where numbers go): parse returns a request or raises ProtocolError, nothing
    else; a request's numbers are finite."""
    try:
        raw = json.dumps(value)
    except ValueError:
        return
    try:
        request = protocol.parse(raw)
    except ProtocolError as refused:
        assert refused.code in protocol.ERROR_CODES
        return
    for number in (getattr(request, name, None) for name in ("x_mm", "y_mm", "t", "force_n", "rate_hz")):
        assert number is None or number == number and abs(number) != float("inf")


def test_the_clock_map_keeps_the_least_delayed_arrival_and_the_spacing_of_a_batch() -> None:
    clock = ClockMap()
    # Client clock 1000 s ahead; messages delayed 5, 1 and 3 ms on the way.
    assert clock.update(1000.0, 0.005) == pytest.approx(-999.995)
    assert clock.update(1000.010, 0.011) == pytest.approx(-999.999)
    assert clock.update(1000.020, 0.023) == pytest.approx(-999.999, abs=2e-6)  # + 1.2 us of skew, not the 3 ms
    offset = clock.update(1000.030, 0.031)
    assert [round(t + offset, 6) for t in (1000.026, 1000.028, 1000.030)] == [0.027, 0.029, 0.031]


def test_the_clock_map_allows_a_slower_client_clock_and_resyncs_after_a_jump_back() -> None:
    clock = ClockMap()
    clock.update(0.0, 10.0)
    slow = clock.update(99.99, 110.0)  # the client's clock lost 10 ms in 100 s: the offset may grow by 1e-4 s/s
    assert slow == pytest.approx(10.01)
    jumped = clock.update(5.0, 110.1)  # its clock went back 95 s
    assert jumped == pytest.approx(105.1)
    assert 5.0 + jumped == pytest.approx(110.1)
    assert 5.0 + clock.update(5.0 + RESYNC_S / 2, 110.1 + RESYNC_S / 2) == pytest.approx(110.1)


def test_the_token_bucket_gives_its_burst_then_its_rate() -> None:
    bucket = TokenBucket(rate_per_s=100.0, burst=10.0)
    assert [bucket.take(1, 0.0) for _ in range(12)].count(True) == 10
    assert not bucket.take(1, 0.005)  # half a token came back
    assert bucket.take(1, 0.010)
    assert not bucket.take(11, 100.0)  # never more than the burst at once
    assert bucket.take(10, 100.0)


def test_one_client_holds_the_finger_until_it_lets_go_or_idles() -> None:
    owner = FingerOwner(idle_s=1.0)
    a, b = object(), object()
    assert owner.claim(a, 0.0) and owner.holder is a
    assert not owner.free_for(b, 0.5) and not owner.claim(b, 0.5)
    assert owner.claim(a, 0.9) and not owner.claim(b, 1.8)  # a's sample at 0.9 s kept it
    assert owner.holder_at(1.8) is a and owner.holder_at(1.95) is None  # idle: nobody holds it for the others
    assert owner.claim(b, 2.0) and owner.holder is b  # a idle for 1.1 s
    assert not owner.release(a) and owner.holder is b
    assert owner.release(b) and owner.holder is None and owner.claim(a, 2.1)


@pytest.fixture
def library(tmp_path: Path) -> TextureLibrary:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "fine.yaml").write_text("description: fine\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n")
    (mine / "passwd.yaml").symlink_to("/etc/passwd")
    os.mkfifo(mine / "fifo.yaml")
    (tmp_path / "outside.yaml").write_text("description: o\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n")
    return TextureLibrary([TEXTURES_DIR, mine])


def _set(library: TextureLibrary, **ref: str) -> tuple[str, str]:
    try:
        texture, source = library.load(SetTexture(type="texture", **ref))
        return "ok", texture.description
    except ProtocolError as refused:
        return refused.code, refused.message


def test_textures_come_by_shipped_name_path_within_the_folders_or_inline_yaml(library: TextureLibrary,
                                                                              tmp_path: Path) -> None:
    assert _set(library, name="grating") == ("ok", "2.5 mm sine grating along the plate's length")
    assert _set(library, path=str(tmp_path / "mine" / "fine.yaml")) == ("ok", "fine")
    assert _set(library, path=str(TEXTURES_DIR / "bitmap_logo.yaml"))[0] == "ok"  # its image in the shipped folder
    inline = "description: inline\nkind: bitmap\nimage: assets/logo.png\nsize_mm: [130, 60]\nfriction: {low: 0.5, high: 1}\n"
    assert _set(library, yaml=inline) == ("ok", "inline")  # relative images from the first folder


@pytest.mark.parametrize(("ref", "code", "fragment"), [
    ({"name": "gratin"}, "texture", "did you mean 'grating'"),
    ({"name": "../grating"}, "texture", "no shipped texture"),
    ({"path": "/etc/passwd"}, "forbidden_path", "outside the folders"),
    ({"path": "OUT/outside.yaml"}, "forbidden_path", "outside the folders"),
    ({"path": "MINE/../outside.yaml"}, "forbidden_path", "outside the folders"),
    ({"path": "MINE/passwd.yaml"}, "forbidden_path", "outside the folders"),  # a link out of the folder
    ({"path": "MINE/fifo.yaml"}, "texture", "not a regular file"),
    ({"path": "MINE/missing.yaml"}, "texture", "missing.yaml"),
    ({"path": "MINE/a\0b.yaml"}, "forbidden_path", "NUL"),
    ({"yaml": "kind: grating\n"}, "texture", "description: required key missing"),
    ({"yaml": "kind: [unclosed\n"}, "texture", "invalid YAML"),
    ({"yaml": "a: &a [*a]\n"}, "texture", "yaml"),
    ({"yaml": "description: x\nkind: bitmap\nimage: /etc/hostname\nsize_mm: [10, 10]\nfriction: {low: 0.5, high: 1}\n"},
     "texture", "outside the folders"),
    ({"yaml": "description: x\nkind: bitmap\nimage: ../../../../../../etc/hostname\nsize_mm: [10, 10]\n"
              "friction: {low: 0.5, high: 1}\n"}, "texture", "outside the folders"),
    ({"yaml": "x" * (5 << 20)}, "texture", "bytes, more than"),
])
def test_texture_requests_outside_the_rules_are_refused(library: TextureLibrary, tmp_path: Path,
                                                        ref: dict[str, str], code: str, fragment: str) -> None:
    given = {key: value.replace("MINE", str(tmp_path / "mine")).replace("OUT", str(tmp_path))
             for key, value in ref.items()}
    refused, message = _set(library, **given)
    assert (refused, fragment in message) == (code, True), message


def test_a_library_of_no_folders_has_the_shipped_one_for_inline_textures() -> None:
    library = TextureLibrary([])  # Settings() names none (the API's default); the command line always does
    assert library.folders == [Path(os.path.realpath(TEXTURES_DIR))]
    assert _set(library, yaml="description: inline\nkind: bitmap\nimage: assets/logo.png\nsize_mm: [130, 60]\n"
                "friction: {low: 0.5, high: 1}\n") == ("ok", "inline")


def test_what_the_server_sends_is_json_a_browser_reads() -> None:
    """NaN and infinities (a statistic with nothing measured yet) go out as null; numpy numbers as numbers."""
    import numpy as np

    from tpad_rt.serve.server import _wire

    sent = _wire({"type": "stats", "p50": float("nan"), "peak": [np.float64(np.inf), np.int64(3)], "ok": 1.5})
    assert json.loads(sent, parse_constant=lambda name: pytest.fail(f"{name} on the wire")) == \
        {"type": "stats", "p50": None, "peak": [None, 3], "ok": 1.5}


class _Kept(logging.Handler):
    """A logging handler that keeps the records."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def _osc_message(address: str, arguments: list[tuple[Any, str]]) -> bytes:
    from pythonosc.osc_message_builder import OscMessageBuilder

    builder = OscMessageBuilder(address)
    for value, tag in arguments:
        builder.add_arg(value, tag)
    return builder.build().dgram


def _bundle(elements: list[bytes]) -> bytes:
    return b"#bundle\0" + bytes(7) + b"\x01" + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def _mutated(packet: bytes, position: int, byte: int, cut: bool) -> bytes:
    """``packet`` cut at ``position``, or with the byte there replaced (both modulo its length)."""
    if not packet:
        return packet
    at = position % len(packet)
    return packet[:at] if cut else packet[:at] + bytes([byte]) + packet[at + 1:]


_OSC_ARGUMENTS = [(1.5, "f"), (2, "i"), (3.0, "d"), (2**40, "h"), ("ab", "s"), (True, "T"), (False, "F"), (None, "N"),
                  (b"blob", "b"), ((1, 2, 3, 4), "m")]
_OSC_PACKETS = st.recursive(
    st.builds(_osc_message, st.sampled_from(["/tpad/ping", "/tpad/finger", "/x", "/"]),
              st.lists(st.sampled_from(_OSC_ARGUMENTS), max_size=4)),
    lambda children: st.lists(children, max_size=5).map(_bundle), max_leaves=12)


@settings(max_examples=400, deadline=None)
@given(st.one_of(_OSC_PACKETS, st.builds(_mutated, _OSC_PACKETS, st.integers(0, 4096), st.integers(0, 255),
                                         st.booleans()), st.binary(max_size=64)))
def test_a_datagram_the_osc_check_passes_is_one_python_osc_reads_without_a_word(data: bytes) -> None:
    """OSC packets (nested bundles, every argument type), with a byte changed or cut short, and random bytes:
    the check refuses them with bad_message, or python-osc parses them into that many messages, logging nothing
    (it logs a warning for an element it cannot identify, and loops forever on a negative element size: the
    check stands between)."""
    from pythonosc.osc_packet import OscPacket

    from tpad_rt.serve.osc import message_count

    try:
        count = message_count(data)
    except ProtocolError as refused:
        assert refused.code == "bad_message" and refused.message.startswith("not an OSC packet this server reads: ")
        return
    kept = _Kept()
    logging.getLogger().addHandler(kept)
    try:
        assert len(OscPacket(data).messages) == count
    finally:
        logging.getLogger().removeHandler(kept)
    assert kept.records == []
