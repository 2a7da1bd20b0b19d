"""``tpad-rt calibrate sweep``: the resonance found through the amplifier emulator (a real process on a real pty),
which simulates its device file's circuit at its contact force; AmpLink.tone's recovery on the virtual link."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from amp_emulator import Emulator
from cli_run import tpad_rt

from tpad_rt.amp.virtual_link import VirtualLink
from tpad_rt.calibrate import sweep
from tpad_rt.calibrate.measurements import read_impedance_sweeps
from tpad_rt.device import Device
from tpad_rt.outputs.serial_amp import AmpLink, parse_serial_url
from tpad_rt.physics import electromech
from tpad_rt.shipped import DEVICES_DIR


@pytest.mark.parametrize(("label", "force_n"), [("default", 0.5), ("SLG_0.4", 2.0)])
def test_the_sweep_finds_the_emulated_devices_resonance_within_0_05_percent(tmp_path: Path, label: str,
                                                                            force_n: float) -> None:
    device = Device.from_file(DEVICES_DIR / f"{label}.yaml")
    out = tmp_path / "fine.csv"
    with Emulator(tmp_path, "--device", label, "--force-n", str(force_n)) as amp:
        # The emulator's STATUS is each carrier's steady state: 20 ms a carrier, whatever the plate's ring-down
        run = tpad_rt("calibrate", "sweep", f"serial://{amp.port}", "--device", label, "--json", "--out", str(out),
                      "--dwell-ms", "20")
        amp.finish()
    assert run.returncode == 0, run.stderr
    found = json.loads(run.stdout)
    l_h, c_f, r_ohm = (float(value) for value in device.motional(force_n))
    series_hz = float(electromech.resonance_hz(l_h, c_f))
    assert found["resonance_hz"] == pytest.approx(series_hz, rel=5e-4)
    assert found["loaded_resonance_hz"] == pytest.approx(float(device.motional_resonance_hz(force_n)), rel=5e-4)
    # At 2 N the plate sits 0.125 % above the carrier it was tuned to: the sweep sees the detuned plate
    assert abs(found["resonance_hz"] / device.carrier_hz - 1) > (1e-3 if force_n == 2.0 else 0.0)
    assert found["motional_r_ohm"] == pytest.approx(r_ohm, rel=0.01)
    assert found["c0_nf"] == pytest.approx(device.c0_f * 1e9, rel=0.01)
    assert found["zero_phase_hz"] is None  # C0's current dominates: a TPaD's piezo stays capacitive
    [fine] = read_impedance_sweeps(out)  # what calibrate impedance and build take
    assert len(fine.freq_hz) == 101 and fine.freq_hz[0] < series_hz < fine.freq_hz[-1]


@pytest.mark.parametrize("label", ["SLG_0.4", "default"])
def test_each_carrier_is_held_five_time_constants_of_the_plate_without_contact(label: str) -> None:
    """A real plate must settle before its STATUS is read: SLG_0.4 (Q about 1080) rings for 15 ms."""
    device = Device.from_file(DEVICES_DIR / f"{label}.yaml")
    tau_s = float(device.envelope_time_constant_s(0.0))
    assert tau_s == max(float(tau) for tau in device.envelope_time_constant_s(device.force_table_n))
    assert sweep.default_dwell_s(device) == pytest.approx(max(0.02, 5 * tau_s))
    assert (sweep.default_dwell_s(device) > 0.05) == (label == "SLG_0.4")


def test_a_tone_the_amplifiers_watchdog_ended_is_started_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """A host held up for longer than the amplifier's watchdog (a loaded machine: the sweep's tone is kept up by a
    Python loop) finds the stream ended; tone() STARTs it again where it stopped and measures the tone applied
    then, not a STATUS from before the watchdog (the amplifier plays the tone again after its trip). On the
    virtual link: the hold is the clock moving on while tone() waits, the amplifier running meanwhile."""
    device = Device.default()
    line = VirtualLink.emulating(device)
    link = AmpLink.open(parse_serial_url("serial://virtual"), carrier_hz=device.carrier_hz, line=line)
    try:
        assert link.info is not None
        link.tone(5.0, 0.05)
        write, held = link._write_tone, []

        def held_up(value: int, play_index: int, fill: int) -> None:
            if not held:  # once: longer than the watchdog, which then ends the stream
                held.append(play_index)
                line.clock.sleep_until_ns(line.clock.now_ns() + 3 * link.info.watchdog_ms * 1_000_000)  # type: ignore[union-attr]
            write(value, play_index, fill)

        monkeypatch.setattr(link, "_write_tone", held_up)
        link.tone(5.0, 0.05)
        assert line.amplifier.counters.watchdog_trips == 1 and held
        # The next carrier of the sweep: the stream plays on (a tone() that returned a STATUS from before the
        # watchdog left the amplifier IDLE, and the next tone never plays)
        carrier_hz = link.set_carrier(device.carrier_hz + 50.0)
        status = link.tone(5.0, 0.05)
    finally:
        link.stop(ramp_ms=5.0)
    assert line.amplifier.counters.watchdog_trips == 1
    assert status.envelope_v == pytest.approx(5.0, abs=2e-3) and status.carrier_hz == pytest.approx(carrier_hz)


def test_a_vanished_amplifier_ends_the_sweep_in_one_line(tmp_path: Path) -> None:
    with Emulator(tmp_path, "--fault", "disconnect:1.5") as amp:
        run = tpad_rt("calibrate", "sweep", f"serial://{amp.port}")
        amp.finish(sig=None)
    run.assert_one_line_error("tpad-rt calibrate sweep: serial:")


@pytest.mark.parametrize(("args", "expected"), [
    (("--drive-v", "41"), "--drive-v: must be <= the device's max_voltage_v (40 V), got 41"),
    (("--from-hz", "40000", "--to-hz", "30000"), "--from-hz (40000) must be below --to-hz (30000)"),
    (("--dwell-ms", "0"), "argument --dwell-ms: must be a number in [1, 10000] (ms), got '0'"),
    (("--plot", "x.gif"), "--plot: must end in .png, .pdf, .svg"),
])
def test_bad_options_end_in_one_line_before_the_port_opens(args: tuple[str, ...], expected: str) -> None:
    tpad_rt("calibrate", "sweep", "serial:///dev/nonexistent-port", *args).assert_one_line_error(expected)


def test_a_missing_port_is_one_line() -> None:
    tpad_rt("calibrate", "sweep", "serial:///dev/nonexistent-port").assert_one_line_error(
        "serial: cannot open /dev/nonexistent-port")


def _has_open(pid: int, path: str) -> bool:
    """Whether process ``pid`` holds ``path`` open (its /proc fd links)."""
    folder = Path(f"/proc/{pid}/fd")
    try:
        return any(os.readlink(folder / name) == path for name in os.listdir(folder))
    except OSError:
        return False


def test_a_signal_during_the_sweep_ramps_down_and_exits_130(tmp_path: Path) -> None:
    with Emulator(tmp_path) as amp:
        process = subprocess.Popen([sys.executable, "-m", "tpad_rt", "calibrate", "sweep", f"serial://{amp.port}"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while process.poll() is None and not _has_open(process.pid, amp.port):
            select.select([], [], [], 0.01)  # poll /proc for the port, opened once the imports are done
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=60)
        recording = amp.finish()
    assert process.returncode == 130, err
    assert err.strip() == "tpad-rt calibrate sweep: interrupted"
    assert len(recording["envelope_v"]) == 0 or recording["envelope_v"][-1] == 0.0
