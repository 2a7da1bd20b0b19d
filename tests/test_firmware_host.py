"""The firmware's host build (``firmware/build/host/tpad-amp``) as a process on a real pty, end to end.

Its command line, device files and recording path are refused in one line; a protocol
exchange over the pty checks INFO against the emulator's for the same device and counts a
bad frame, with nothing timed. Three ``realtime`` items judge it at full rate: ``play``
against it, a frozen host (SIGSTOP) and its watchdog on the firmware's own clock, and
``calibrate sweep`` finding the simulated resonance. The core's rules themselves are tested
on a virtual clock by the core's unit tests and the conformance suite.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cli_run import tpad_rt
from firmware_amp import DEFAULT_DEVICE, HostAmp, tpad_amp
from pty_host import WAIT_S, PtyHost
from tpad_rt.amp import wire
from tpad_rt.amp.emulator import Circuit, amplifier_info
from tpad_rt.amp.wire import Code, State, Type
from tpad_rt.device import Device
from tpad_rt.physics import electromech

TESTS = Path(__file__).resolve().parent
#: The watchdog's promise (A4): output 0 within this of the last valid frame (s).
WATCHDOG_S = 0.050


def run_amp(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(tpad_amp()), *args], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=60)


def assert_one_line_error(done: subprocess.CompletedProcess[str], expected: str) -> None:
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert done.stdout == "", done.stdout
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("tpad-amp: "), done.stderr
    assert expected in done.stderr, done.stderr


DEVICE = str(DEFAULT_DEVICE)


@pytest.mark.parametrize(("args", "expected"), [
    ((), "--device FILE is required"),
    (("--device",), "--device needs a value"),
    (("--device", DEVICE, "--bogus"), "unknown option '--bogus'"),
    (("--device", DEVICE, "stray"), "unexpected argument 'stray'"),
    (("--device", DEVICE, "--device", DEVICE), "--device given twice"),
    (("--device", DEVICE, "--duration", "0"), "--duration: must be a number in (0, 86400] (s), got '0'"),
    (("--device", DEVICE, "--duration", "nan"), "got 'nan'"),
    (("--device", DEVICE, "--duration", "inf"), "got 'inf'"),
    (("--device", DEVICE, "--duration", "1e999"), "got '1e999'"),
    (("--device", DEVICE, "--duration", "0x10"), "got '0x10'"),
    (("--device", DEVICE, "--force-n", "-1"), "--force-n: must be a number in [0, 50] (N), got '-1'"),
    (("--device", DEVICE, "--seed", "-1"), "--seed: must be a whole number from 0 to 4294967295, got '-1'"),
    (("--device", DEVICE, "--seed", "4294967296"), "got '4294967296'"),
    (("--device", DEVICE, "--fault", "melt:1"), "unknown fault 'melt' in 'melt:1'; one of drop:RATE"),
    (("--device", DEVICE, "--fault", "drop:1.5"), "--fault drop: must be a number in [0, 1] (a probability)"),
    (("--device", DEVICE, "--fault", "corrupt:NaN"), "--fault corrupt: must be a number in [0, 1]"),
    (("--device", DEVICE, "--fault", "delay:10001"), "--fault delay: must be a number in [0, 10000] (ms)"),
    (("--device", DEVICE, "--fault", "stall:1"), "--fault: stall is written stall:AT_S:FOR_S, got 'stall:1'"),
    (("--device", DEVICE, "--fault", "stall:1:-2"), "--fault stall FOR_S: must be a number in [0, 86400] (s)"),
    (("--device", DEVICE, "--fault", "overcurrent:1:2"), "overcurrent is written overcurrent:AT_S"),
    (("--device", DEVICE, "--fault", "disconnect:1", "--fault", "disconnect:2"),
     "--fault disconnect given twice; it may be given once"),
])
def test_a_bad_flag_is_one_line_and_status_1(args: tuple[str, ...], expected: str) -> None:
    assert_one_line_error(run_amp(*args), expected)


def test_help_lists_every_option_fault_and_recorded_column() -> None:
    done = run_amp("--help")
    assert done.returncode == 0 and done.stderr == ""
    for word in ("--device", "--record", "--duration", "--fault", "--force-n", "--seed", "drop:RATE", "corrupt:RATE",
                 "delay:MS", "stall:AT_S:FOR_S", "overcurrent:AT_S", "disconnect:AT_S", "t_s", "event", "envelope_v",
                 "carrier_hz", "index", "state", "output_peak_v", "current_a_rms", "last_frame_s"):
        assert word in done.stdout, word


GOOD = DEFAULT_DEVICE.read_text()
#: The default device file's line of circuit.c0_nf (1-based).
C0_LINE = GOOD.splitlines().index("  c0_nf: 9.88") + 1


@pytest.mark.parametrize(("old", "new", "expected"), [
    ("  c0_nf: 9.88", "\tc0_nf: 9.88", f"line {C0_LINE}: a tab in the indentation"),
    ("  c0_nf: 9.88\n", "", "circuit.c0_nf is missing"),
    ("  c0_nf: 9.88", "  c0_nf: 1e9", f"line {C0_LINE}: circuit.c0_nf must be in [0.001, 100000], got 1e+09"),
    ("  c0_nf: 9.88", "  c0_nf: .nan", f"line {C0_LINE}: circuit.c0_nf must be a number"),
    ("  c0_nf: 9.88", "  c0_nf: [9.88]", f"line {C0_LINE}: circuit.c0_nf must be a number"),
    ("  c0_nf: 9.88", "  c0_nf: 9.88\n  c0_nf: 9.9", f"line {C0_LINE + 1}: 'circuit.c0_nf' given twice"),
    ("  shunt_ohm: 100.0", "   shunt_ohm: 100.0", f"line {C0_LINE + 1}: indented 3 spaces where 2 are expected"),
    ("force_n: [0.0, 0.2,", "force_n: [0.0, 0.0,", "circuit.force_n must be strictly increasing"),
    ("force_n: [0.0, 0.2,", "force_n: [0.2,", "circuit.motional_l_h must have as many items as force_n (8), got 9"),
    ("motional_r_ohm: [965.5,", "motional_r_ohm: [oops,", "'oops' in a flow list is not a number"),
    ("1854.0, 2150.0]", "1854.0, 2150.0", "a flow list must end with ']' on its line"),
    ("carrier_hz: 31360.0", "carrier_hz: 150000.0", "carrier_hz must be in [1000, 100000], got 150000"),
    ("format_version: 2", "format_version: 1", "format_version must be in [2, 2], got 1"),
    ("label: SLG_0.56", "label: &anchor SLG_0.56", "line 3: '&' starts a YAML construct"),
    ("label: SLG_0.56", "label:\n- SLG_0.56", "line 4: expected 'key: value'"),
    ("Table 1 #2)'", "Table 1 #2)", "line 4: a quoted string that does not end on its line"),
    ("label:", "x" * 2000 + ":", "line 3: a line longer than 1024 characters"),
    ("label:", "la\x01bel:", "line 3: a control character (byte 0x01)"),
    ("label:", "la\x00bel:", "line 3: a control character (byte 0x00)"),
    # the core refuses the board it makes: full scale (1.25 x max_voltage_v) past 1000 V
    ("max_voltage_v: 40.0", "max_voltage_v: 800.1",
     "the amplifier it makes is out of range: full_scale_mv must be 1 .. 1000000 (1000 V)"),
])
def test_a_bad_device_file_is_one_line_naming_the_file_and_line(tmp_path: Path, old: str, new: str,
                                                                 expected: str) -> None:
    path = tmp_path / "device.yaml"
    assert old in GOOD
    path.write_text(GOOD.replace(old, new, 1))
    done = run_amp("--device", str(path), "--duration", "0.01")
    assert_one_line_error(done, f"tpad-amp: {path}")
    assert expected in done.stderr, done.stderr


def test_every_shipped_device_file_is_read(tmp_path: Path) -> None:
    """Each shipped device starts (and ends at once with --duration)."""
    for path in sorted(DEFAULT_DEVICE.parent.glob("*.yaml")):
        done = run_amp("--device", str(path), "--duration", "0.01")
        assert done.returncode == 0 and done.stdout.startswith("amplifier on /dev/pts/"), (path, done.stderr)


def test_a_missing_device_or_an_unwritable_recording_is_one_line(tmp_path: Path) -> None:
    assert_one_line_error(run_amp("--device", str(tmp_path / "none.yaml")),
                          f"{tmp_path / 'none.yaml'}: cannot open the device file (No such file or directory)")
    assert_one_line_error(run_amp("--device", str(tmp_path)), f"{tmp_path}, line 1: cannot read the device file")
    assert_one_line_error(run_amp("--device", DEVICE, "--record", str(tmp_path)), f"{tmp_path}: not a file name")
    target = tmp_path / "missing" / "amp.csv"
    assert_one_line_error(run_amp("--device", DEVICE, "--record", str(target)),
                          f"{target}: the recording cannot be written (No such file or directory)")
    assert list(tmp_path.iterdir()) == []  # nothing left behind


def test_info_matches_the_emulators_and_a_bad_frame_is_counted(tmp_path: Path) -> None:
    """Over the real pty, nothing timed: HELLO is answered with INFO echoing its nonce, with the limits the emulator
    gives the same device; a frame with a bad CRC is counted in frames_bad, never answered; --duration and
    SIGTERM end the process with status 0, its summary and a recording of what it applied."""
    device = Device.from_file(DEFAULT_DEVICE)
    expected = amplifier_info(device, Circuit(device, 0.5))
    with HostAmp(tmp_path) as amp:
        host = PtyHost(amp.port)
        info = host.hello(0xC0FFEE01)
        assert info.hello_nonce == 0xC0FFEE01 and info.firmware == "tpad-amp 1.0"
        for field in ("full_scale_mv", "max_mv", "carrier_min_mhz", "carrier_max_mhz", "max_current_ma", "measures",
                      "buffer_samples", "watchdog_ms", "status_period_ms", "envelope_rates_hz"):
            assert getattr(info, field) == getattr(expected, field), field
        bad = bytearray(wire.encode(Type.KEEPALIVE, host.seq, b""))
        bad[-2] ^= 0x01  # the CRC's high byte (then the delimiter)
        host.write(bytes(bad))
        host.status(lambda status: status.frames_bad == 1, "frames_bad = 1")
        again = host.hello(0xC0FFEE02)  # a new session: counters from 0, the same INFO but its nonce
        assert again == info.__class__(**{**vars(info), "hello_nonce": 0xC0FFEE02})
        host.status(lambda status: status.frames_ok == 1 and status.frames_bad == 0 and status.state == State.IDLE,
                    "a STATUS of the new session")
        recording = amp.finish()
        host.close()
    assert amp.summary.startswith("tpad-amp stopped by a signal: frames_ok=1 frames_bad=0 ")
    assert amp.counters["faults"] == 0 and recording.shape == (0,)


def _unread_bytes(fd: int) -> int:
    """Bytes the amplifier wrote that the host's end ``fd`` has not read (FIONREAD)."""
    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]


def _wait_until(condition: Callable[[], bool], what: str) -> None:
    """Poll ``condition`` every millisecond until true; AssertionError after WAIT_S (a safety net)."""
    deadline_s = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline_s, f"no {what} within {WAIT_S:g} s"
        select.select([], [], [], 0.001)


def test_hello_drops_the_bytes_the_host_has_not_read(tmp_path: Path) -> None:
    """A host that read nothing for a while finds STATUS frames of the old session queued; its HELLO drops them (the
    emulator's discard_output), so that the first frame it reads after is the INFO answering it, seq 0."""
    with HostAmp(tmp_path) as amp:
        host = PtyHost(amp.port)
        host.hello(1)
        _wait_until(lambda: _unread_bytes(host.fd) > 1000, "STATUS frames piling up")
        host.seq = 0
        host.send(Type.HELLO, wire.Hello("test", 2).pack())
        _wait_until(lambda: _unread_bytes(host.fd) < 1000, "the stale bytes dropped")
        first = host.wait(lambda frame: True, "a frame")
        amp.finish()
        host.close()
    assert first.type == Type.INFO and first.seq == 0 and wire.Info.unpack(first.payload).hello_nonce == 2


def test_an_overcurrent_fault_is_reported_and_refuses_start(tmp_path: Path) -> None:
    """--fault overcurrent:AT_S: STATUS reports the fault (A6) and FAULT; START is refused until HELLO."""
    with HostAmp(tmp_path, "--fault", "overcurrent:0.2") as amp:
        host = PtyHost(amp.port)
        host.hello(3)
        host.status(lambda status: status.faults == 1 and status.state == State.FAULT, "the overcurrent fault")
        carrier = host.send(Type.SET_CARRIER, wire.SetCarrier(31_360_000).pack())
        assert host.ack(carrier).code == Code.OK
        start = host.send(Type.START, wire.Start(16000, 0, 16).pack())
        assert host.ack(start).code == Code.FAULT
        amp.finish()
        host.close()
    assert amp.counters["faults"] == 1 and amp.counters["frames_rejected"] == 1


def test_delay_and_stall_faults_hold_the_hosts_bytes_back(tmp_path: Path) -> None:
    """--fault delay:300: INFO comes no sooner than 300 ms after HELLO was written; --fault stall:0:0.3: nothing is
    read before 0.3 s on the firmware's clock (its first STATUS after HELLO says so). Lower bounds: a slow machine
    only adds to them."""
    with HostAmp(tmp_path / "delay", "--fault", "delay:300") as amp:
        host = PtyHost(amp.port)
        written_s = time.monotonic()
        host.hello(4)
        assert time.monotonic() - written_s >= 0.3
        amp.finish()
        host.close()
    with HostAmp(tmp_path / "stall", "--fault", "stall:0:0.3") as amp:
        host = PtyHost(amp.port)
        host.hello(5)
        first = host.status(lambda status: True, "a STATUS")
        amp.finish()
        host.close()
    assert first.time_us >= 300_000 + 5_000  # read at 0.3 s at the earliest, then one status period


def test_duration_and_disconnect_end_by_themselves_with_status_0(tmp_path: Path) -> None:
    with HostAmp(tmp_path / "duration", "--duration", "0.2") as amp:
        amp.finish(None)
    assert amp.summary.startswith("tpad-amp ran for --duration: frames_ok=0 ")
    with HostAmp(tmp_path / "disconnect", "--fault", "disconnect:0.2") as amp:
        host = PtyHost(amp.port)
        assert host.ended()
        amp.finish(None)
        host.close()
    assert amp.summary.startswith("tpad-amp disconnected: ")


@pytest.mark.realtime
def test_play_streams_the_grating_with_no_bad_frame_or_gap(tmp_path: Path) -> None:
    """``tpad-rt play textures/grating.yaml --output serial://PTY --duration 3`` against the host build."""
    with HostAmp(tmp_path) as amp:
        run = tpad_rt("play", "textures/grating.yaml", "--output", f"serial://{amp.port}", "--duration", "3")
        recording = amp.finish()
    assert run.returncode == 0, run.stderr
    assert amp.counters["frames_bad"] == 0 and amp.counters["sequence_gaps"] == 0, amp.summary
    assert amp.counters["frames_ok"] > 5000 and amp.counters["watchdog_trips"] == 0, amp.summary
    played = recording[(recording["event"] == 0) & (recording["index"] >= 0)]
    assert len(played) > 2.5 * 16_000
    device = Device.from_file(DEFAULT_DEVICE)
    peak_v = float(np.abs(played["envelope_v"]).max())
    assert 0.5 * device.max_voltage_v < peak_v <= device.max_voltage_v  # the grating's levels, under the clamp
    assert float(recording["output_peak_v"].max()) <= device.max_voltage_v


@pytest.mark.realtime
def test_a_frozen_host_brings_the_output_to_zero_within_50_ms_on_the_firmwares_clock(tmp_path: Path) -> None:
    """A host streaming 10 V, 63 ms ahead, is stopped (SIGSTOP): the watchdog trips with 10 V still playing from the
    buffer, and the recording shows the output at 0 within 50 ms of the last valid frame, both times on the
    firmware's own clock."""
    with HostAmp(tmp_path) as amp:
        host = subprocess.Popen([sys.executable, str(TESTS / "stream_host.py"), amp.port, "10"], cwd=TESTS,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONPATH": os.pathsep.join((str(TESTS.parent), str(TESTS)))})
        try:
            assert host.stdout is not None
            assert host.stdout.readline() == "streaming\n", host.communicate(timeout=60)
            host.send_signal(signal.SIGSTOP)
            watcher = PtyHost(amp.port)  # the frozen host reads nothing: STATUS comes to the test
            watcher.status(lambda status: status.watchdog_trips == 1 and status.state == State.IDLE
                           and status.envelope_mv == 0, "the watchdog's trip and 0 V")
            watcher.close()
            recording = amp.finish()
        finally:
            host.kill()
            host.communicate(timeout=60)
    [trip] = np.flatnonzero(recording["event"] == 1)
    last_frame_s = float(recording["last_frame_s"][trip])
    after = recording[trip:]
    zero = after[(after["event"] == 0) & (after["envelope_v"] == 0.0) & (after["output_peak_v"] == 0.0)]
    assert len(zero) > 0 and np.all(after["envelope_v"][after["t_s"] >= zero["t_s"][0]] == 0.0)
    before = recording[:trip][recording["event"][:trip] == 0]
    assert before["index"][-1] >= 0 and before["envelope_v"][-1] == pytest.approx(10.0, abs=0.01)  # still playing
    to_zero_s = float(zero["t_s"][0]) - last_frame_s
    print(f"output at 0 {to_zero_s * 1000:.2f} ms after the last valid frame (firmware clock)")
    assert 0.0 < to_zero_s <= WATCHDOG_S


@pytest.mark.realtime
def test_calibrate_sweep_finds_the_simulated_resonance_within_0_05_percent(tmp_path: Path) -> None:
    """The circuit the firmware simulates is the device file's at --force-n: the sweep's fit finds its loaded
    resonance (the device model's, computed here) through the core's carrier and measurement."""
    force_n = 0.5
    device = Device.from_file(DEFAULT_DEVICE)
    with HostAmp(tmp_path, "--force-n", str(force_n)) as amp:
        run = tpad_rt("calibrate", "sweep", f"serial://{amp.port}", "--device", "default", "--json", "--dwell-ms", "20")
        amp.finish()
    assert run.returncode == 0, run.stderr
    found = json.loads(run.stdout)
    l_h, c_f, _ = (float(value) for value in device.motional(force_n))
    loaded_hz = float(device.motional_resonance_hz(force_n))
    print(f"loaded resonance found {found['loaded_resonance_hz']:.3f} Hz, model {loaded_hz:.3f} Hz: "
          f"{(found['loaded_resonance_hz'] / loaded_hz - 1) * 100:+.5f} %")
    assert found["loaded_resonance_hz"] == pytest.approx(loaded_hz, rel=5e-4)
    assert found["resonance_hz"] == pytest.approx(float(electromech.resonance_hz(l_h, c_f)), rel=5e-4)
