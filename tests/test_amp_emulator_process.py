"""``tpad-rt amp emulate`` as a process on a real pty, end to end: the real-component tier of the emulator's tests.

The protocol itself (every rule, fault and time) is tested on the virtual clock in
tests/test_amp_emulator.py; here the emulator runs in its own process (tests/amp_emulator.py)
with the test as its host on the pty it opened, speaking through tpad_rt/amp/wire.py. The
host waits for what it expects with a generous deadline, a safety net only; nothing
judges the timing but the one ``realtime`` test, whose watchdog needs the wall clock to
pass.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from amp_emulator import Emulator
from pty_host import WAIT_S, PtyHost
from tpad_rt.amp import wire
from tpad_rt.amp.emulator import RECORDED_COLUMNS
from tpad_rt.amp.wire import Code, State, Type
from tpad_rt.device import Device

DEVICE = Device.default()
RESONANCE_MHZ = round(DEVICE.carrier_hz * 1000)
#: The scalars every recording holds beside its columns (tpad-rt amp emulate --help).
SCALARS = {"frames_ok", "frames_bad", "frames_rejected", "sequence_gaps", "underruns", "watchdog_trips", "faults",
           "watchdog_trip_t_s", "envelope_hz", "full_scale_mv", "max_mv", "slew_mv_per_ms", "truncated"}


def check_recording(recording: dict[str, np.ndarray]) -> None:
    """Every column and scalar, the columns of one length."""
    assert set(recording) == set(RECORDED_COLUMNS) | SCALARS
    assert len({len(recording[name]) for name in RECORDED_COLUMNS}) == 1


@pytest.mark.realtime
def test_streams_on_a_pty_and_its_watchdog_trips(tmp_path: Path) -> None:
    """HELLO answered with INFO, a buffer of samples plays, the host falls silent and the watchdog trips (A4) with
    most of it unplayed; SIGTERM ends the process with status 0, its summary and its recording. The samples sent
    in one write arrive together, so no scheduling delay can keep them apart."""
    with Emulator(tmp_path) as emulator:
        host = PtyHost(emulator.port)
        info = host.hello(0x5EED0001)
        assert info.firmware.startswith("tpad-emu") and info.buffer_samples == 1024
        value = round(10_000 / info.full_scale_mv * 32767)  # 10 V
        carrier = host.send(Type.SET_CARRIER, wire.SetCarrier(RESONANCE_MHZ).pack())
        assert host.ack(carrier).code == Code.OK
        started = host.seq
        host.write(wire.encode(Type.START, started, wire.Start(8000, 0, 1024).pack()) + b"".join(
            wire.encode(Type.ENVELOPE, started + 1 + k, wire.Envelope(64 * k, np.full(64, value, np.int16)).pack())
            for k in range(16)))
        assert host.ack(started).code == Code.OK
        host.status(lambda status: status.state == State.RUNNING, "RUNNING")
        tripped = host.status(lambda status: status.watchdog_trips == 1, "the watchdog's trip")
        assert tripped.buffer_fill == 0
        host.status(lambda status: status.state == State.IDLE and status.envelope_mv == 0, "IDLE at 0 V")
        recording = emulator.finish()
        host.close()
    assert emulator.summary.startswith("amplifier emulator stopped by a signal: frames_ok=19 ")
    check_recording(recording)
    index = recording["index"]
    played = np.flatnonzero(index >= 0)
    assert 0 < len(played) < 1024 and (index[played] == np.arange(len(played))).all()  # tripped: not played out
    assert np.allclose(recording["envelope_v"][played], value / 32767 * info.full_scale_mv / 1000, rtol=1e-12)
    assert recording["watchdog_trips"] == 1 and len(recording["watchdog_trip_t_s"]) == 1
    assert recording["envelope_v"][-1] == 0 and recording["envelope_hz"] == 8000


def test_a_host_may_close_and_reopen_the_port_and_sigkill_ends_the_line(tmp_path: Path) -> None:
    """The emulator keeps its own end of the pty: a host that closes the port and opens it again is answered; its
    SIGKILL ends the line, which the host's read sees."""
    with Emulator(tmp_path) as emulator:
        host = PtyHost(emulator.port)
        host.hello(1)
        host.close()
        host = PtyHost(emulator.port)
        host.hello(2)
        emulator.process.kill()
        assert host.ended()
        host.close()
        assert emulator.process.wait(WAIT_S) == -signal.SIGKILL


def test_duration_and_disconnect_end_with_status_0(tmp_path: Path) -> None:
    """--duration and a disconnect fault each end the process by itself with status 0, its summary and its
    recording."""
    with Emulator(tmp_path / "duration", "--duration", "0.2") as emulator:
        recording = emulator.finish(None)
    assert emulator.summary.startswith("amplifier emulator ran for --duration: frames_ok=0 ")
    check_recording(recording)
    assert recording["t_s"].shape == (0,) and recording["envelope_hz"] == 0
    with Emulator(tmp_path / "disconnect", "--fault", "disconnect:0.3") as emulator:
        emulator.finish(None)
    assert emulator.summary.startswith("amplifier emulator disconnected: ")


def test_serves_an_existing_port_and_sigint_ends_it(tmp_path: Path) -> None:
    """--port: the emulator opens a terminal it is given; the host talks on the other end. SIGINT (Ctrl-C) ends it
    with status 0."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        with Emulator(tmp_path, "--port", path) as emulator:
            os.close(slave)
            slave = -1
            assert emulator.port == path
            host = PtyHost(fd=master)
            assert host.hello(3).firmware.startswith("tpad-emu")
            host.status(lambda status: status.state == State.IDLE, "STATUS")
            emulator.finish(signal.SIGINT)
        assert emulator.summary.startswith("amplifier emulator stopped by a signal: frames_ok=1 ")
    finally:
        os.close(master)
        if slave >= 0:
            os.close(slave)
