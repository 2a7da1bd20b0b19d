"""The amplifier's codec (tpad_rt/amp/wire.py) against docs/amp-protocol.md: the worked bytes of section 7,
the CRC check value, COBS as section 2.1 describes it, the checks of 2.3 steps 1-2 and the message layouts."""

from __future__ import annotations

import numpy as np
import pytest
from cobs import cobs

from tpad_rt.amp import wire

#: Section 7: (body, line) of the KEEPALIVE, the HELLO and the ENVELOPE.
WORKED = {
    "keepalive": ("02 06 05 00 fd 24", "04 02 06 05 03 fd 24 00"),
    "hello": ("02 01 00 00 74 70 61 64 2d 72 74 00 00 00 00 00 b9 79 37 9e c0 c4",
              "03 02 01 01 08 74 70 61 64 2d 72 74 01 01 01 01 07 b9 79 37 9e c0 c4 00"),
    "envelope": ("02 04 03 00 00 00 00 00 00 00 00 40 00 c0 ff 7f 6a 87",
                 "04 02 04 03 01 01 01 01 01 01 01 02 40 06 c0 ff 7f 6a 87 00"),
}
#: The same frames as (type, seq, payload).
MESSAGES = {
    "keepalive": (wire.Type.KEEPALIVE, 5, b""),
    "hello": (wire.Type.HELLO, 0, wire.Hello("tpad-rt", 0x9E3779B9).pack()),
    "envelope": (wire.Type.ENVELOPE, 3, wire.Envelope(0, np.array([0, 16384, -16384, 32767], np.int16)).pack()),
}


def test_crc_check_value() -> None:
    assert wire.crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize("name", WORKED)
def test_worked_bytes_encode(name: str) -> None:
    body, line = (bytes.fromhex(text) for text in WORKED[name])
    assert wire.encode(*MESSAGES[name]) == line
    assert wire.crc16(body[:-2]).to_bytes(2, "little") == body[-2:]


@pytest.mark.parametrize("name", WORKED)
def test_worked_bytes_decode(name: str) -> None:
    line = bytes.fromhex(WORKED[name][1])
    frames = wire.FrameSplitter().feed(line)
    assert len(frames) == 1 and frames[0] == line[:-1]
    frame = wire.decode(frames[0])
    type_, seq, payload = MESSAGES[name]
    assert frame == wire.Frame(wire.VERSION, type_, seq, payload)


def test_worked_payloads_unpack() -> None:
    assert wire.Hello.unpack(MESSAGES["hello"][2]) == wire.Hello("tpad-rt", 0x9E3779B9)
    envelope = wire.Envelope.unpack(MESSAGES["envelope"][2])
    assert envelope.first_index == 0 and envelope.samples.tolist() == [0, 16384, -16384, 32767]


def test_cobs_as_section_2_1_says() -> None:
    """``11 22 00 33`` encodes to ``03 11 22 02 33``, the empty body to ``01``; a block of code 255 inserts no 0x00."""
    assert cobs.encode(bytes.fromhex("11 22 00 33")) == bytes.fromhex("03 11 22 02 33")
    assert cobs.encode(b"") == b"\x01"
    payload = bytes([0x11, 0x22]) + bytes(range(1, 255)) * 2  # runs of 254 non-zero bytes: code 255 blocks
    encoded = wire.encode(wire.Type.ENVELOPE, 7, payload)
    assert 0 not in encoded[:-1] and encoded[-1] == 0
    assert 255 in encoded
    assert wire.decode(encoded[:-1]) == wire.Frame(wire.VERSION, wire.Type.ENVELOPE, 7, payload)


@pytest.mark.parametrize("encoded", [
    b"\x05\x01\x02",            # a code pointing past the end
    b"\x01",                    # the empty body
    bytes.fromhex("04 01 06 05 03 21 be"),  # the KEEPALIVE with its CRC changed
    bytes.fromhex("04 01 06 05 02 21"),     # the KEEPALIVE cut short
])
def test_bad_frames_are_none(encoded: bytes) -> None:
    assert wire.decode(encoded) is None


def test_body_length_limits() -> None:
    """A body of MAX_BODY bytes (256 samples) decodes; a longer one is bad, and encode refuses it."""
    samples = np.arange(256, dtype=np.int16)
    line = wire.encode(wire.Type.ENVELOPE, 1, wire.Envelope(9, samples).pack())
    assert len(line) <= wire.MAX_ENCODED + 1
    assert wire.Envelope.unpack(wire.decode(line[:-1]).payload).samples.tolist() == samples.tolist()
    with pytest.raises(ValueError):
        wire.encode(wire.Type.ENVELOPE, 1, wire.Envelope(9, np.zeros(257, np.int16)).pack())
    body = bytes([wire.VERSION, 4, 0, 0]) + bytes(4 + 2 * 257)
    body += wire.crc16(body).to_bytes(2, "little")
    assert wire.decode(cobs.encode(body)) is None


def test_splitter_ignores_empty_frames_and_cuts_over_long_runs() -> None:
    splitter = wire.FrameSplitter()
    keepalive = bytes.fromhex(WORKED["keepalive"][1])
    assert splitter.feed(b"\x00\x00" + keepalive[:3]) == []
    assert splitter.feed(keepalive[3:] + b"\x00") == [keepalive[:-1]]
    assert splitter.feed(b"\x01" * (wire.MAX_ENCODED - 1)) == []
    assert splitter.feed(b"\x01\x01") == [None]  # more than MAX_ENCODED bytes: one bad frame
    assert splitter.feed(b"\x07" * 10_000_000) == []  # still discarding, nothing kept
    assert splitter.feed(b"\x00" + keepalive) == [keepalive[:-1]]
    assert splitter.feed(b"\x01" * wire.MAX_ENCODED + b"\x00") == [b"\x01" * wire.MAX_ENCODED]


def test_layouts_have_the_documented_sizes() -> None:
    assert wire.MAX_ENCODED == 526
    assert wire.PAYLOAD_BYTES == {
        wire.Type.HELLO: 16, wire.Type.SET_CARRIER: 4, wire.Type.START: 10, wire.Type.STOP: 2,
        wire.Type.KEEPALIVE: 0, wire.Type.INFO: 92, wire.Type.STATUS: 56, wire.Type.ACK: 8,
    }


def test_info_status_ack_round_trip_at_their_offsets() -> None:
    info = wire.Info("tpad-emu 1.0", "EMU-1", (8000, 16000, 0, 0), 10_000_000, 80_000_000, 10, 50_000, 40_000,
                     100_000, 1024, 256, 50, 5, 7, 82, 0xDEADBEEF)
    payload = info.pack()
    assert wire.Info.unpack(payload) == info
    assert payload[:12] == b"tpad-emu 1.0" and payload[12:16] == bytes(4)
    assert int.from_bytes(payload[84:88], "little") == 0xDEADBEEF  # hello_nonce (version 2)
    assert int.from_bytes(payload[36:40], "little") == 16000
    assert int.from_bytes(payload[60:64], "little") == 50_000
    assert int.from_bytes(payload[72:74], "little") == 1024
    assert payload[80] == 7 and payload[81:84] == bytes(3)
    assert int.from_bytes(payload[88:92], "little") == 82
    status = wire.Status(2**32 - 1, 2**32 - 2, 1024, 2, 1, 3, 4, 5, 6, 7, 8, 65535, -9000, -40_000, 28_284, 54_074,
                         31_360_000)
    payload = status.pack()
    assert wire.Status.unpack(payload) == status
    assert int.from_bytes(payload[38:40], "little", signed=True) == -9000
    assert int.from_bytes(payload[40:44], "little", signed=True) == -40_000
    assert int.from_bytes(payload[52:56], "little") == 31_360_000
    ack = wire.Ack(65535, wire.Type.START, wire.Code.FAULT, 2**32 - 1)
    assert wire.Ack.unpack(ack.pack()) == ack and ack.pack()[2:4] == bytes([3, 9])
    start = wire.Start(16000, 2**32 - 1, 1024)
    assert wire.Start.unpack(start.pack()) == start
