"""The micro:bit firmware under QEMU (``firmware/run-qemu``): the smoke test of the ARM build (docs/firmware.md
"QEMU (micro:bit)").

One ``realtime`` item plays the grating for 3 s through ``serial://`` to the firmware on QEMU's ``microbit``
machine, at the settings docs/firmware.md states for it (4 ms frames, a 40 ms buffer), and reads the firmware's
counters twice: in play's summary (the last STATUS the host read) and in run-qemu's (a STATUS read after the run,
counters since play's HELLO). The other items judge no time: run-qemu ended by SIGINT with no host (no session to
report), and its refusals (a bad flag, a board QEMU cannot run, no QEMU, no build).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from amp_process import AmplifierProcess, parse_counters
from cli_run import Run, tpad_rt
from conftest import require_program
from firmware_build import build

REPO = Path(__file__).resolve().parents[1]
RUN_QEMU = REPO / "firmware" / "run-qemu"
#: The URL settings the QEMU UART carries cleanly (docs/firmware.md "QEMU (micro:bit)").
SETTINGS = "frame_ms=4&buffer_ms=40"
#: Seconds run-qemu may take to start (QEMU's start, its pty poll of 1 s, the firmware's answer) or to end.
WAIT_S = 60.0
#: play's summary line of the amplifier's counters (tpad_rt/drivers/serial_stream.py).
PLAY_COUNTERS = re.compile(r"amplifier: tpad-amp [^;]*; frames (?P<ok>\d+) applied, (?P<bad>\d+) bad, "
                           r"(?P<refused>\d+) refused, (?P<gaps>\d+) sequence gaps; (?P<underruns>\d+) samples underrun")
PLAY_FRAMES = re.compile(r"played [\d.]+ s of drive in [\d.]+ s: (?P<frames>\d+) frames")


class RunQemu(AmplifierProcess):
    """``firmware/run-qemu microbit`` in its own process; ``.port`` is the pty to give the host."""

    def __init__(self) -> None:
        super().__init__([str(RUN_QEMU), "microbit"], "amplifier on ", "run-qemu", cwd=REPO)

    def stop(self, sig: int = signal.SIGTERM) -> str:
        """End it with ``sig`` (by PID), check it exited 0, and return its last line."""
        return self.end(sig).strip().splitlines()[-1]

    def finish(self) -> dict[str, int]:
        """stop(), and the counters its last line gives."""
        last = self.stop()
        assert last.startswith("amplifier stopped by a signal: frames_ok="), last
        return parse_counters(last)


@pytest.mark.realtime
def test_play_through_the_microbit_firmware_under_qemu_has_no_bad_frames() -> None:
    require_program("qemu-system-arm")
    build("microbit")
    with RunQemu() as amp:
        done = tpad_rt("play", "textures/grating.yaml", "--output", f"serial://{amp.port}?{SETTINGS}",
                       "--duration", "3")
        firmware = amp.finish()
    assert done.returncode == 0, done.stderr
    seen = PLAY_COUNTERS.search(done.stdout)
    rendered = PLAY_FRAMES.search(done.stdout)
    assert seen is not None and rendered is not None, done.stdout
    assert int(seen["bad"]) == 0 and int(seen["gaps"]) == 0, seen.group(0)
    assert firmware["frames_bad"] == 0 and firmware["sequence_gaps"] == 0, firmware
    assert firmware["faults"] == 0 and firmware["watchdog_trips"] == 0, firmware
    # Every frame the host rendered reached the firmware whole (played, or refused when it came too late), and
    # most of them played: the firmware ran the stream, not only the handshake.
    frames = int(rendered["frames"])
    assert firmware["frames_ok"] + firmware["frames_rejected"] >= frames, (frames, firmware)
    assert firmware["frames_ok"] > frames / 2, (frames, firmware, seen.group(0))


def test_run_qemu_without_a_host_ends_on_sigint_saying_there_was_no_session() -> None:
    require_program("qemu-system-arm")
    build("microbit")
    with RunQemu() as amp:
        last = amp.stop(signal.SIGINT)
    assert last == "amplifier stopped by a signal: no session (no STATUS: the firmware had no HELLO)"


def run_qemu(*args: str, env: dict[str, str] | None = None, script: Path = RUN_QEMU) -> Run:
    done = subprocess.run([str(script), *args], cwd=REPO, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=WAIT_S, env={**os.environ, **(env or {})}, check=False)
    return Run(done.returncode, done.stdout, done.stderr, 0.0)


def test_run_qemu_refuses_a_board_qemu_cannot_run() -> None:
    done = run_qemu("nucleo-g474re")
    done.assert_one_line_error("run-qemu: no QEMU machine for board 'nucleo-g474re' (QEMU runs: microbit)")
    assert done.stdout == ""


def test_run_qemu_refuses_a_bad_flag_in_one_line() -> None:
    run_qemu("microbit", "--bogus").assert_one_line_error("run-qemu: error: unrecognized arguments: --bogus")


def test_run_qemu_without_qemu_says_which_binary_is_missing() -> None:
    done = run_qemu("microbit", env={"TPAD_QEMU_ARM": "qemu-system-arm-not-installed"})
    done.assert_one_line_error("run-qemu: qemu-system-arm-not-installed not found (install Debian's "
                               "qemu-system-arm, or name the binary in TPAD_QEMU_ARM)")


def test_run_qemu_without_a_build_says_how_to_make_it(tmp_path: Path) -> None:
    # A copy of the script in a firmware folder with nothing built; any existing binary stands in for QEMU.
    script = tmp_path / "firmware" / "run-qemu"
    script.parent.mkdir()
    shutil.copy2(RUN_QEMU, script)
    done = run_qemu("microbit", script=script, env={"TPAD_QEMU_ARM": sys.executable, "PYTHONPATH": str(REPO)})
    done.assert_one_line_error("run-qemu: firmware/build/microbit/tpad-amp.elf is not built: run "
                               "`make -C firmware microbit`, or `firmware/run-qemu microbit --build`")
