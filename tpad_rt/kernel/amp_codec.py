"""The host's codec of the amplifier protocol (docs/amp-protocol.md, version 2): COBS, CRC-16, message layouts.

API map
-------
crc16(data, length) -> int
    CRC-16/IBM-3740 of ``data[:length]`` (section 2.2)
cobs_encode(body, length, out) -> int
    COBS-encode ``body[:length]`` into ``out`` and append the 0x00 delimiter; bytes written
cobs_decode(encoded, length, body) -> int
    decode ``encoded[:length]`` (no delimiter) into ``body``; its length, or -1 if malformed
seal(frame, payload_length, msg_type, seq, out) -> int
    fill in the header and CRC of the body ``frame`` (payload already at ``PAYLOAD``) and
    encode it into ``out`` (section 2): bytes to send
open_body(body, length) -> int
    check a decoded body (length, CRC, version): its message type, or a negative CHECK_* code
get_u16/get_u32/get_i16/get_i32, put_u16/put_u32/put_i16
    little-endian fields of a uint8 buffer
MSG_*, ACK_*, INFO_*, STATUS_*, START_*, ENVELOPE_*
    message types, ACK codes, and field offsets from the payload's start

Every function is a numba kernel (njit, nogil, cache): the serial streamer
(:mod:`tpad_rt.kernel.amp_stream`) calls them without the GIL, and the host's Python
side calls the same ones for its handshake, so there is one host implementation. The
emulator (:mod:`tpad_rt.amp`) is a second, separate one: the tests check each against
the document's worked bytes and against each other.
"""

from __future__ import annotations

import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel.cache_stamp import stamp_cache

stamp_cache(__file__)

#: The protocol version this host speaks (byte 0 of every body).
VERSION = 2
#: Header: version (u8), type (u8), seq (u16); the payload starts at PAYLOAD.
HEADER_BYTES = 4
PAYLOAD = HEADER_BYTES
CRC_BYTES = 2
#: Shortest body (a header and a CRC) and longest (an ENVELOPE of 256 samples).
MIN_BODY = HEADER_BYTES + CRC_BYTES
MAX_BODY = 522
#: Most COBS bytes a MAX_BODY body encodes to, with its delimiter.
MAX_ENCODED = MAX_BODY + MAX_BODY // 254 + 2
#: Most samples in one ENVELOPE frame (the protocol's bound; INFO may say fewer).
MAX_FRAME_SAMPLES = 256

# --- message types (section 3) ------------------------------------------------
MSG_HELLO = 0x01
MSG_SET_CARRIER = 0x02
MSG_START = 0x03
MSG_ENVELOPE = 0x04
MSG_STOP = 0x05
MSG_KEEPALIVE = 0x06
MSG_INFO = 0x81
MSG_STATUS = 0x82
MSG_ACK = 0x83

# --- payload lengths ----------------------------------------------------------------
HELLO_BYTES = 16
HELLO_NAME_BYTES = 12         # HELLO: ``host`` (string), then ``nonce`` (u32) at HELLO_NONCE
HELLO_NONCE = 12
SET_CARRIER_BYTES = 4
START_BYTES = 10
STOP_BYTES = 2
INFO_BYTES = 92
STATUS_BYTES = 56
ACK_BYTES = 8

# --- ACK codes (section 3.2) ------------------------------------------------------
ACK_OK = 0
ACK_BAD_VERSION = 1
ACK_UNKNOWN_TYPE = 2
ACK_BAD_LENGTH = 3
ACK_OUT_OF_RANGE = 4
ACK_NO_CARRIER = 5
ACK_BAD_RATE = 6
ACK_NOT_STARTED = 7
ACK_OUT_OF_WINDOW = 8
ACK_FAULT = 9
ACK_NAMES = ("OK", "BAD_VERSION", "UNKNOWN_TYPE", "BAD_LENGTH", "OUT_OF_RANGE", "NO_CARRIER", "BAD_RATE",
             "NOT_STARTED", "OUT_OF_WINDOW", "FAULT")

# --- field offsets, from the payload's start -------------------------------------
START_ENVELOPE_HZ = 0         # u32
START_INDEX = 4               # u32
START_PREFILL = 8             # u16
ENVELOPE_FIRST_INDEX = 0      # u32, then i16 samples
ENVELOPE_SAMPLES = 4
ACK_ACKED_SEQ = 0             # u16
ACK_ACKED_TYPE = 2            # u8
ACK_CODE = 3                  # u8
ACK_VALUE = 4                 # u32
INFO_FIRMWARE = 0             # 16 bytes
INFO_SERIAL = 16              # 16 bytes
INFO_RATES = 32               # 4 x u32
INFO_CARRIER_MIN_MHZ = 48
INFO_CARRIER_MAX_MHZ = 52
INFO_CARRIER_STEP_MHZ = 56
INFO_FULL_SCALE_MV = 60
INFO_MAX_MV = 64
INFO_SLEW_MV_PER_MS = 68
INFO_BUFFER_SAMPLES = 72      # u16
INFO_MAX_FRAME_SAMPLES = 74   # u16
INFO_WATCHDOG_MS = 76         # u16
INFO_STATUS_PERIOD_MS = 78    # u16
INFO_MEASURES = 80            # u8
INFO_HELLO_NONCE = 84         # u32: the nonce of the HELLO this INFO answers
INFO_MAX_CURRENT_MA = 88      # u32
STATUS_TIME_US = 0            # u32
STATUS_PLAY_INDEX = 4         # u32
STATUS_BUFFER_FILL = 8        # u16
STATUS_STATE = 10             # u8
STATUS_FAULTS = 11            # u8
STATUS_FRAMES_OK = 12         # u32 counters ...
STATUS_FRAMES_BAD = 16
STATUS_FRAMES_REJECTED = 20
STATUS_SEQUENCE_GAPS = 24
STATUS_UNDERRUNS = 28
STATUS_WATCHDOG_TRIPS = 32
STATUS_LAST_SEQ = 36          # u16
STATUS_PHASE_CDEG = 38        # i16
STATUS_ENVELOPE_MV = 40       # i32
STATUS_VOLTAGE_MV_RMS = 44    # u32
STATUS_CURRENT_UA_RMS = 48    # u32
STATUS_CARRIER_MHZ = 52       # u32

# --- amplifier states and fault bits (STATUS) ---------------------------------------
STATE_IDLE = 0
STATE_PRIMING = 1
STATE_RUNNING = 2
STATE_RAMPING = 3
STATE_FAULT = 4
STATE_NAMES = ("IDLE", "PRIMING", "RUNNING", "RAMPING", "FAULT")
FAULT_BITS = ((1, "overcurrent"), (2, "overvoltage"), (4, "overtemperature"), (8, "supply"))

# --- open_body's refusals -------------------------------------------------------------
CHECK_SHORT = -1              # shorter than a header and a CRC, or longer than MAX_BODY
CHECK_CRC = -2                # CRC mismatch
CHECK_VERSION = -3            # another protocol version (byte 0)

_KERNEL = dict(nogil=True, cache=True, error_model="numpy")


def _crc_table() -> np.ndarray:
    """The 256-entry table of CRC-16/IBM-3740 (poly 0x1021, MSB first)."""
    table = np.zeros(256, dtype=np.uint16)
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
        table[byte] = crc & 0xFFFF
    return table


_CRC_TABLE = _crc_table()


@njit(**_KERNEL)
def crc16(data: np.ndarray, length: int) -> int:
    """CRC-16/IBM-3740 (init 0xFFFF, no reflection, no final XOR) of ``data[:length]`` (uint8)."""
    crc = 0xFFFF
    for i in range(length):
        crc = ((crc << 8) & 0xFFFF) ^ _CRC_TABLE[((crc >> 8) ^ data[i]) & 0xFF]
    return crc


@njit(**_KERNEL)
def cobs_encode(body: np.ndarray, length: int, out: np.ndarray) -> int:
    """COBS-encode ``body[:length]`` into ``out`` (room for ``length + length // 254 + 2``), then a 0x00.

    Returns the bytes written, delimiter included.
    """
    code_at = 0
    code = 1
    n = 1
    for i in range(length):
        byte = body[i]
        if byte == 0:
            out[code_at] = code
            code_at = n
            n += 1
            code = 1
        else:
            out[n] = byte
            n += 1
            code += 1
            if code == 0xFF:
                out[code_at] = code
                code_at = n
                n += 1
                code = 1
    out[code_at] = code
    out[n] = 0
    return n + 1


@njit(**_KERNEL)
def cobs_decode(encoded: np.ndarray, length: int, body: np.ndarray) -> int:
    """Decode the COBS bytes ``encoded[:length]`` (without the delimiter) into ``body``.

    Returns the body's length, or -1 if the bytes are not COBS (a 0x00, a block running
    past the end) or the body would not fit in ``body``.
    """
    i = 0
    n = 0
    while i < length:
        code = int(encoded[i])  # not uint8: i + code must not wrap (NumPy 2 keeps uint8 when the kernel runs as Python)
        if code == 0 or i + code > length:  # a block is its code byte and code - 1 data bytes
            return -1
        i += 1
        for _ in range(code - 1):
            byte = encoded[i]
            if byte == 0 or n >= body.shape[0]:
                return -1
            body[n] = byte
            n += 1
            i += 1
        if code < 0xFF and i < length:
            if n >= body.shape[0]:
                return -1
            body[n] = 0
            n += 1
    return n


@njit(**_KERNEL)
def put_u16(buffer: np.ndarray, at: int, value: int) -> None:
    """Store ``value`` (taken mod 2**16) little-endian at ``buffer[at]``."""
    buffer[at] = value & 0xFF
    buffer[at + 1] = (value >> 8) & 0xFF


@njit(**_KERNEL)
def put_i16(buffer: np.ndarray, at: int, value: int) -> None:
    """Store ``value`` (two's complement, -32768..32767) little-endian at ``buffer[at]``."""
    put_u16(buffer, at, value & 0xFFFF)


@njit(**_KERNEL)
def put_u32(buffer: np.ndarray, at: int, value: int) -> None:
    """Store ``value`` (taken mod 2**32) little-endian at ``buffer[at]``."""
    for k in range(4):
        buffer[at + k] = (value >> (8 * k)) & 0xFF


@njit(**_KERNEL)
def get_u16(buffer: np.ndarray, at: int) -> int:
    """The little-endian u16 at ``buffer[at]``."""
    return int(np.int64(buffer[at]) | (np.int64(buffer[at + 1]) << 8))


@njit(**_KERNEL)
def get_i16(buffer: np.ndarray, at: int) -> int:
    """The little-endian i16 at ``buffer[at]``."""
    value = get_u16(buffer, at)
    return value - 0x10000 if value >= 0x8000 else value


@njit(**_KERNEL)
def get_u32(buffer: np.ndarray, at: int) -> int:
    """The little-endian u32 at ``buffer[at]``."""
    value = np.int64(0)
    for k in range(4):
        value |= np.int64(buffer[at + k]) << (8 * k)
    return int(value)


@njit(**_KERNEL)
def get_i32(buffer: np.ndarray, at: int) -> int:
    """The little-endian i32 at ``buffer[at]``."""
    value = get_u32(buffer, at)
    return value - 0x100000000 if value >= 0x80000000 else value


@njit(**_KERNEL)
def seal(frame: np.ndarray, payload_length: int, msg_type: int, seq: int, out: np.ndarray) -> int:
    """Write the header (version, ``msg_type``, ``seq``) and the CRC around the payload already in
    ``frame[PAYLOAD:PAYLOAD + payload_length]``, and COBS-encode the body into ``out`` (room for
    MAX_ENCODED). Returns the bytes to send, delimiter included."""
    frame[0] = VERSION
    frame[1] = msg_type
    put_u16(frame, 2, seq)
    body_length = PAYLOAD + payload_length
    put_u16(frame, body_length, crc16(frame, body_length))
    return cobs_encode(frame, body_length + CRC_BYTES, out)


@njit(**_KERNEL)
def open_body(body: np.ndarray, length: int) -> int:
    """Check a decoded body of ``length`` bytes (section 2.3, steps 1-3): its type (byte 1),
    or CHECK_SHORT, CHECK_CRC or CHECK_VERSION."""
    if not MIN_BODY <= length <= MAX_BODY:
        return CHECK_SHORT
    if crc16(body, length - CRC_BYTES) != get_u16(body, length - CRC_BYTES):
        return CHECK_CRC
    if body[0] != VERSION:
        return CHECK_VERSION
    return int(body[1])
