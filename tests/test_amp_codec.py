"""The host's amplifier codec (tpad_rt.kernel.amp_codec) against reference implementations (the ``cobs`` and
``crc`` packages) and the worked bytes of docs/amp-protocol.md section 7."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from cobs import cobs
from crc import Calculator, Crc16
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tpad_rt.kernel import amp_codec as codec

DOC = Path(__file__).resolve().parents[1] / "docs" / "amp-protocol.md"
REFERENCE_CRC = Calculator(Crc16.IBM_3740)


def as_array(data: bytes) -> np.ndarray:
    """``data`` as a writable uint8 array (one byte at least, so that numba gets an array)."""
    return np.frombuffer(data or b"\0", dtype=np.uint8).copy()


def encoded(data: bytes) -> bytes:
    """The host codec's COBS bytes of ``data``, delimiter included."""
    out = np.zeros(len(data) + len(data) // 254 + 2, dtype=np.uint8)
    return bytes(out[:codec.cobs_encode(as_array(data), len(data), out)])


def decoded(data: bytes) -> bytes | None:
    """The host codec's decoding of COBS ``data`` (no delimiter), None if it refuses it."""
    body = np.zeros(max(len(data), 1), dtype=np.uint8)
    size = codec.cobs_decode(as_array(data), len(data), body)
    return None if size < 0 else bytes(body[:size])


def test_crc_check_value() -> None:
    assert codec.crc16(as_array(b"123456789"), 9) == 0x29B1


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_crc_equals_the_reference(data: bytes) -> None:
    assert codec.crc16(as_array(data), len(data)) == REFERENCE_CRC.checksum(data)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=600), st.lists(st.sampled_from([0, 1, 255]), max_size=600).map(bytes)))
def test_cobs_encoding_equals_the_reference_and_decodes_back(data: bytes) -> None:
    line = encoded(data)
    assert line == cobs.encode(data) + b"\0"
    assert b"\0" not in line[:-1]
    assert decoded(line[:-1]) == data


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=40))
@example(b"\x01" * 17 + b"\xef")  # a block past the end at 17 + 239 = 256, which wraps to 0 in uint8
def test_cobs_decoding_refuses_what_the_reference_refuses(data: bytes) -> None:
    try:
        expected: bytes | None = cobs.decode(data)
    except cobs.DecodeError:
        expected = None
    assert decoded(data) == expected


def test_cobs_decoding_refuses_a_body_too_large_for_its_buffer() -> None:
    line = encoded(b"\x11" * 100)[:-1]
    body = np.zeros(99, dtype=np.uint8)
    assert codec.cobs_decode(as_array(line), len(line), body) == -1


def doc_vectors() -> list[tuple[bytes, bytes]]:
    """(body, line) pairs of the document's worked bytes."""
    text = DOC.read_text()
    pairs = re.findall(r"body  ([0-9a-f ]+)\nline  ([0-9a-f ]+)\n", text)
    assert len(pairs) == 3, "docs/amp-protocol.md section 7 has three worked frames"
    return [(bytes.fromhex(body), bytes.fromhex(line)) for body, line in pairs]


@pytest.mark.parametrize("number", range(3))
def test_seal_makes_the_documents_worked_bytes(number: int) -> None:
    body, line = doc_vectors()[number]
    frame = np.zeros(codec.MAX_BODY, dtype=np.uint8)
    payload = body[codec.PAYLOAD:-codec.CRC_BYTES]
    frame[codec.PAYLOAD:codec.PAYLOAD + len(payload)] = np.frombuffer(payload, dtype=np.uint8)
    out = np.zeros(codec.MAX_ENCODED, dtype=np.uint8)
    size = codec.seal(frame, len(payload), body[1], int.from_bytes(body[2:4], "little"), out)
    assert bytes(out[:size]) == line
    assert REFERENCE_CRC.checksum(body[:-2]) == int.from_bytes(body[-2:], "little")


def test_open_body_checks_length_crc_and_version() -> None:
    body, _ = doc_vectors()[0]  # a KEEPALIVE
    assert codec.open_body(as_array(body), len(body)) == codec.MSG_KEEPALIVE
    assert codec.open_body(as_array(body + b"\x00"), len(body) + 1) == codec.CHECK_CRC
    assert codec.open_body(as_array(body[:5]), 5) == codec.CHECK_SHORT
    assert codec.open_body(as_array(body * 100), codec.MAX_BODY + 1) == codec.CHECK_SHORT
    flipped = bytearray(body)
    flipped[2] ^= 0x10
    assert codec.open_body(as_array(bytes(flipped)), len(body)) == codec.CHECK_CRC
    other = bytes([codec.VERSION + 1]) + body[1:4]
    other += REFERENCE_CRC.checksum(other).to_bytes(2, "little")
    assert codec.open_body(as_array(other), len(other)) == codec.CHECK_VERSION


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 2**16 - 1), st.integers(-(2**15), 2**15 - 1),
       st.integers(-(2**31), 2**31 - 1))
def test_little_endian_fields_round_trip(u32: int, u16: int, i16: int, i32: int) -> None:
    buffer = np.zeros(16, dtype=np.uint8)
    codec.put_u32(buffer, 0, u32)
    codec.put_u16(buffer, 4, u16)
    codec.put_i16(buffer, 6, i16)
    codec.put_u32(buffer, 8, i32 & 0xFFFFFFFF)
    assert bytes(buffer[:4]) == u32.to_bytes(4, "little") and codec.get_u32(buffer, 0) == u32
    assert codec.get_u16(buffer, 4) == u16 and codec.get_i16(buffer, 6) == i16 and codec.get_i32(buffer, 8) == i32
