"""The firmware's portable core (firmware/core): its C unit tests, their line coverage, and the core
as a shared library (what the conformance suite drives with ctypes)."""

from __future__ import annotations

import ctypes
import re

from amp_targets import HalBoard, board_layout_mismatch, load_core
from firmware_build import build, make_target
from tpad_rt.amp import wire

#: The least line coverage of firmware/core/*.c (the issue's gate; the Makefile's COVERAGE_MIN).
MIN_COVERAGE_PERCENT = 90.0
#: Section 7's HELLO (seq 0, host "tpad-rt", nonce 0x9E3779B9) as it goes on the line.
HELLO_LINE = bytes.fromhex("0302010108747061642d72740101010107b979379ec0c400")


def test_core_unit_tests_pass() -> None:
    """``make -C firmware test``: the core's unit tests (worked bytes, A1-A8 on exact times, faults,
    adversarial frames, synthesis and demodulation against references) built with ASan and UBSan."""
    done = make_target("test")
    assert done.returncode == 0, done.stdout[-3000:]
    assert "core tests: all passed" in done.stdout


def test_core_line_coverage_is_at_least_90_percent() -> None:
    """``make -C firmware coverage`` passes its gate, and the total it prints is at least 90 %."""
    done = make_target("coverage")
    assert done.returncode == 0, done.stdout[-3000:]
    found = re.search(r"core line coverage: ([0-9.]+) % of (\d+) lines", done.stdout)
    assert found is not None, done.stdout[-3000:]
    assert float(found.group(1)) >= MIN_COVERAGE_PERCENT
    assert int(found.group(2)) > 500  # every core file was measured


def test_the_ctypes_board_has_hal_hs_layout() -> None:
    """tests/amp_targets.py's HalBoard (what every ctypes caller builds) has hal.h's hal_board_t layout:
    its size and every field's offset as the library reports them (amp_board_layout)."""
    assert board_layout_mismatch(load_core(build("lib"))) is None


def test_core_library_answers_hello_through_ctypes() -> None:
    """``make -C firmware lib``: libtpadamp.so loads (no board symbols missing) and answers the
    document's HELLO with an INFO that echoes its nonce."""
    library = load_core(build("lib"))
    board = HalBoard(b"py", 192000, 125000, 100000, 10_000_000, 80_000_000, 2000, 7, 5000, 1000)
    amp = ctypes.create_string_buffer(library.amp_sizeof())
    assert library.amp_init(amp, ctypes.byref(board), b"PY-1", 0) == 0
    hello = (ctypes.c_uint8 * len(HELLO_LINE)).from_buffer_copy(HELLO_LINE)
    library.amp_receive(amp, hello, len(HELLO_LINE), 1000)
    out = (ctypes.c_uint8 * 512)()
    sent_bytes = library.amp_transmit(amp, out, 512)
    frames = wire.FrameSplitter().feed(bytes(out[:sent_bytes]))
    assert len(frames) == 1 and frames[0] is not None
    frame = wire.decode(frames[0])  # the Python codec reads the C core's INFO
    assert frame is not None and (frame.version, frame.type, frame.seq) == (2, wire.Type.INFO, 0)
    info = wire.Info.unpack(frame.payload)
    assert (info.firmware, info.serial, info.hello_nonce) == ("tpad-amp 1.0", "PY-1", 0x9E3779B9)
    assert (info.full_scale_mv, info.max_mv, info.measures, info.max_current_ma) == (125000, 100000, 7, 2000)
